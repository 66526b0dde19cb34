"""The role pages (vehicle, relay, client) and an index linking them.

Each page embeds its configuration as ``<script type="application/json" id="config">`` so the
ES modules need no globals: ICE servers from :class:`~app.server.config.Settings`, the
signaling path, the default rosbridge URL (this server's ``/rosbridge``) and what the query
string asks for.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from fastapi.templating import Jinja2Templates

from app.protocol.constants import PROFILES, ROLES, Role
from app.resources import TEMPLATES_DIR
from app.server.config import Settings

router = APIRouter()
templates = Jinja2Templates(directory=TEMPLATES_DIR)


def _ws_base(request: Request) -> str:
    """``ws://host:port`` (or ``wss://``) of this server as the browser reached it."""
    scheme = "wss" if request.url.scheme == "https" else "ws"
    return f"{scheme}://{request.url.netloc}"


def page_config(request: Request, role: Role) -> dict[str, Any]:
    """What a role page needs to run on its own, ``?auto=1`` included."""
    settings: Settings = request.app.state.settings
    query = request.query_params
    profile = query.get("profile", "default")
    return {
        "role": role,
        "iceServers": [s.model_dump(exclude_none=True) for s in settings.ice_servers],
        "wsPath": "/ws",
        "room": query.get("room", "default"),
        "name": query.get("name", ""),
        "token": query.get("token"),
        "auto": query.get("auto") in ("1", "true", "yes"),
        # An unknown profile falls back to the default rather than breaking the page.
        "profile": profile if profile in PROFILES else "default",
        "rosbridge": query.get("rosbridge") or f"{_ws_base(request)}/rosbridge",
        "ros": "2" if query.get("ros") == "2" else "1",
    }


def _render(request: Request, role: Role) -> HTMLResponse:
    return templates.TemplateResponse(
        request, f"{role}.html", {"config": page_config(request, role), "role": role}
    )


@router.get("/", response_class=HTMLResponse)
async def index(request: Request) -> HTMLResponse:
    """Links to the three role pages for one room."""
    room = request.query_params.get("room", "default")
    return templates.TemplateResponse(request, "index.html", {"room": room, "roles": ROLES})


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
