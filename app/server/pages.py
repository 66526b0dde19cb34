"""The role pages (vehicle, relay, client) and an index linking them.

Each page embeds its configuration (:class:`app.protocol.page.PageConfig`) as ``<script
type="application/json" id="config">`` so the ES modules need no globals: the signaling path, the
default rosbridge URL (this server's ``/rosbridge``) and what the query string asks for, the
control law's numbers, and the protocol constants and data-channel schemas rendered from
:mod:`app.protocol` (``config.protocol``). ICE servers are not in it: each login reply carries
them, with TURN credentials minted for that login. Nor is the token: the page reads it from its
URL fragment, which no server sees.
"""

from __future__ import annotations

import math
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from fastapi.templating import Jinja2Templates

from app.protocol.control import (
    DEFAULT_PROFILE,
    PROFILES,
    ControlConfig,
    control_config,
    with_standoff,
)
from app.protocol.page import (
    BaseConfig,
    PageConfig,
    page_protocol,
    robot_config,
    to_json,
)
from app.protocol.robot import DEFAULT_ROBOT, PRESETS, Robot
from app.protocol.rooms import DEFAULT_ROOM, ROLES, Role
from app.protocol.ros import AUTO, ROS_CONFIG, ROS_SETTINGS
from app.resources import TEMPLATES_DIR
from app.server.tls import insecure_rosbridge

router = APIRouter()
templates = Jinja2Templates(directory=TEMPLATES_DIR)


def _ws_base(request: Request) -> str:
    """``ws://host:port`` (or ``wss://``) of this server as the browser reached it."""
    scheme = "wss" if request.url.scheme == "https" else "ws"
    return f"{scheme}://{request.url.netloc}"


def page_config(request: Request, role: Role) -> dict[str, Any]:
    """What a role page needs to run on its own, ``?auto=1`` included, as the page reads it."""
    query = request.query_params
    asked = query.get("profile", DEFAULT_PROFILE)
    # An unknown profile falls back to the default rather than breaking the page.
    profile = PROFILES[asked if asked in PROFILES else DEFAULT_PROFILE]
    robot, robot_error = _robot(query.get("robot"))
    own_rosbridge = f"{_ws_base(request)}/rosbridge"
    rosbridge = query.get("rosbridge") or own_rosbridge
    ros = query.get("ros", AUTO)
    config = PageConfig(
        role=role,
        ws_path="/ws",
        room=query.get("room", DEFAULT_ROOM),
        name=query.get("name", ""),
        auto=query.get("auto") in ("1", "true", "yes"),
        # The relay paces its snapshots by the relay profile the vehicle profile pairs with.
        profile=profile.relay_profile if role == "relay" else profile.name,
        operation=profile.operation,
        control=_control(query.get("standoff")),
        # ?spawn=0 switches the spawn step off, ?preview=0 the relay's preview (unattended);
        # no robot but a turtlesim has the step.
        spawn_step=robot.turtlesim and query.get("spawn") not in ("0", "false", "no"),
        preview=query.get("preview") not in ("0", "false", "no"),
        rosbridge=rosbridge,
        # The page's token (read from the URL fragment) goes only to this server's rosbridge.
        rosbridge_auth=rosbridge == own_rosbridge,
        rosbridge_error=insecure_rosbridge(rosbridge, request.url.scheme),
        ros=ros if ros in ROS_SETTINGS else AUTO,
        ros_types=ROS_CONFIG,
        # The simulated arena for the client's map, when the server simulates one.
        arena_map=request.app.state.simulator.simulation.arena_map(),
        robot=robot_config(robot),
        robot_error=robot_error,
        protocol=page_protocol(),
    )
    converted: dict[str, Any] = to_json(config)
    return converted


def base_config() -> dict[str, Any]:
    """The config of a page with no role (index, parity): the protocol alone."""
    converted: dict[str, Any] = to_json(BaseConfig(page_protocol()))
    return converted


def _standoff(text: str | None) -> float | None:
    """``?standoff=M`` in metres; None (the profile's own) when absent or not a distance >= 0,
    just as an unknown profile falls back to the default."""
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) and value >= 0 else None


def _robot(name: str | None) -> tuple[Robot, str | None]:
    """``?robot=NAME``: a preset (default turtlesim). An unknown name is not guessed at: the
    page says so and drives nothing (the description stays turtlesim's, unused)."""
    if name is None or name in PRESETS:
        return PRESETS[name or DEFAULT_ROBOT], None
    known = ", ".join(PRESETS)
    return PRESETS[DEFAULT_ROBOT], f"no robot preset named {name!r} (robot= is one of {known})"


def _control(standoff: str | None) -> ControlConfig:
    """The control law's numbers for ``control.js``; ``?standoff=M`` sets the follow distance.
    The page's pilot fits its profile to the robot (``core/pilot.js``)."""
    return control_config(
        {**PROFILES, "follow": with_standoff(PROFILES["follow"], _standoff(standoff))}
    )


def _render(request: Request, role: Role) -> HTMLResponse:
    return templates.TemplateResponse(
        request, f"{role}.html", {"config": page_config(request, role), "role": role}
    )


@router.get("/", response_class=HTMLResponse)
async def index(request: Request) -> HTMLResponse:
    """Links to the three role pages for one room."""
    room = request.query_params.get("room", DEFAULT_ROOM)
    return templates.TemplateResponse(
        request, "index.html", {"room": room, "roles": ROLES, "config": base_config()}
    )


@router.get("/vehicle", response_class=HTMLResponse)
async def vehicle(request: Request) -> HTMLResponse:
    """The vehicle: camera, ``autopilot`` data channel, roslib.js to a rosbridge."""
    return _render(request, "vehicle")


@router.get("/relay", response_class=HTMLResponse)
async def relay(request: Request) -> HTMLResponse:
    """The relay ("intermediate server"): forwards video, runs operations, sends goals."""
    return _render(request, "relay")


@router.get("/client", response_class=HTMLResponse)
async def client(request: Request) -> HTMLResponse:
    """The client: watches video and route, picks the operation, starts and stops piloting."""
    return _render(request, "client")
