"""The config every page embeds (``<script type="application/json" id="config">``), as dataclasses.

What a page knows of the protocol -- profile names, channel labels, the frame tag's layout, the
lock's rule, the control law's numbers, the ROS type names, the data-channel schemas -- is
rendered from the Python that owns it, each fact once, so no JS module types it again. The
dataclasses below say which facts and where in the config; :func:`to_json` is the one
conversion into what the page parses (camelCase field names, JSON numbers). The server fills a
:class:`PageConfig` per request (``app/server/pages.py``); ``js/config.js`` parses it, and
``schema.js`` validates data-channel messages against ``protocol.schemas``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import Any

from app.protocol import relay_profiles
from app.protocol.channels import (
    AUTOPILOT_CHANNEL,
    AUTOPILOT_STATE_CHANNEL,
    CONTROL_CHANNEL,
    GOAL_AGE_WINDOW_S,
    GOAL_MAX_AGE_S,
    GOAL_MAX_CLOCK_SKEW_S,
    GOAL_SEQ_BURST,
    GOAL_SEQ_RATE_HZ,
    STATE_CHANNEL_MAX_RETRANSMITS,
    STATE_CHANNEL_ORDERED,
    channel_schemas,
)
from app.protocol.control import PROFILES as VEHICLE_PROFILES
from app.protocol.control import ControlConfig
from app.protocol.frametag import LAYOUT, FrameTagLayout
from app.protocol.link_health import HEALTH, HealthLimits
from app.protocol.lock import LockRule
from app.protocol.opencv import RELAY_OPENCV_BUILD, OpenCvBuild
from app.protocol.robot import Robot, TypeTable, type_table
from app.protocol.rooms import DEFAULT_ROOM, ROLES, Role
from app.protocol.ros import RosConfig, RosSetting
from app.protocol.video import CLIENT_FORWARD_SCALE_DOWN, VIDEO_SIZE


def camel(name: str) -> str:
    """``snake_case`` as ``camelCase``."""
    head, *rest = name.split("_")
    return head + "".join(part.capitalize() for part in rest)


@dataclass(frozen=True)
class Verbatim:
    """JSON that reaches the page as it is, not walked again on every page served (the
    data-channel schemas: generated JSON Schema, large, whose keys are not field names)."""

    json: dict[str, Any]


def to_json(value: Any) -> Any:
    """``value`` as the page reads it: a dataclass becomes an object of its fields, named in
    camelCase; a mapping keeps its keys (profile names, channel labels are data, not field
    names); tuples become arrays; an infinity becomes null (JSON has none: "no limit",
    "never"); :class:`Verbatim` is left as it is."""
    if isinstance(value, Verbatim):
        return value.json
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {camel(f.name): to_json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {key: to_json(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [to_json(item) for item in value]
    if isinstance(value, float) and math.isinf(value):
        return None
    return value


@dataclass(frozen=True)
class ProfileNames:
    """The relay's profiles and the vehicle's."""

    relay: tuple[str, ...]
    vehicle: tuple[str, ...]


@dataclass(frozen=True)
class RelayPacing:
    """How often a relay profile takes a snapshot (None: every decoded frame)."""

    snapshot_period_ms: int | None


@dataclass(frozen=True)
class ChannelLabels:
    """The data channels' labels."""

    autopilot: str
    autopilot_state: str
    control: str


@dataclass(frozen=True)
class StateChannelOptions:
    """RTCDataChannelInit of the lossy state channel."""

    ordered: bool
    max_retransmits: int


@dataclass(frozen=True)
class GoalFreshness:
    """The latest-wins gate's numbers (``freshness.js``)."""

    max_age_s: float
    window_s: float
    max_skew_s: float
    seq_rate_hz: float
    seq_burst: int


@dataclass(frozen=True)
class VideoSize:
    """The frame size the vehicle page asks its camera for."""

    width: int
    height: int


@dataclass(frozen=True)
class PageProtocol:
    """What every page gets, with a role or without (``config.protocol``)."""

    roles: tuple[Role, ...]
    default_room: str
    profiles: ProfileNames
    default_profile: str
    relay_profiles: dict[str, RelayPacing]
    channels: ChannelLabels
    state_channel_options: StateChannelOptions
    goal_freshness: GoalFreshness
    video: VideoSize
    # How much smaller the relay's forward to a client is, per side.
    client_forward_scale_down: float
    frame_tag: FrameTagLayout
    lock: LockRule
    health: HealthLimits
    # The OpenCV.js build the analyzer loads unless the page's ?opencv= names another.
    opencv_build: OpenCvBuild
    # schemas[channel label][receiving role]: JSON Schema (draft 2020-12 subset, schema.js).
    schemas: Verbatim


@dataclass(frozen=True)
class BillboardMark:
    """A billboard of the simulated arena as the client's map draws it: a picture ``width``
    metres wide where it starts (``x``, ``y``, facing ``yaw``), and the closed path it walks
    (empty when it stands still)."""

    name: str
    kind: str
    width: float
    x: float
    y: float
    yaw: float
    walk: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class ArenaMap:
    """The simulated arena, for the client's map, when the server simulates one: its size, the
    robot's radius and camera's field of view (the wedge drawn from its pose), the billboards,
    and where to read their places now (``GET state_path?room=R``, every ``state_period_ms``)."""

    width: float
    depth: float
    robot_radius: float
    hfov: float
    billboards: tuple[BillboardMark, ...]
    state_path: str
    state_period_ms: int


@dataclass(frozen=True)
class PlacedMark:
    """Where one billboard stands now (``GET /arena/state``)."""

    name: str
    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class ArenaState:
    """What ``GET /arena/state`` answers: the arena's time (s) and its billboards' places."""

    t: float
    billboards: tuple[PlacedMark, ...]


@dataclass(frozen=True)
class RobotConfig:
    """The robot the vehicle page drives (``?robot=NAME``): its description, what follows from
    it, and its type names in every flavour (``core/rosflavour.js`` picks among them)."""

    description: Robot
    # A turtlesim has the spawn step and the terrain's walls.
    turtlesim: bool
    teleport_service: str | None
    types: TypeTable


def robot_config(robot: Robot) -> RobotConfig:
    """What the vehicle page needs to know of ``robot``."""
    return RobotConfig(robot, robot.turtlesim, robot.teleport_service, type_table(robot))


@dataclass(frozen=True)
class PageConfig:
    """A role page's whole config: what it needs to run on its own, ``?auto=1`` included."""

    role: Role
    ws_path: str
    room: str
    name: str
    auto: bool
    # The vehicle profile, or on the relay page the relay profile it pairs with.
    profile: str
    # The operation the relay starts with for the vehicle profile asked (None: the spec's
    # default).
    operation: str | None
    # The control law's numbers, the world's geometry among them.
    control: ControlConfig
    # The vehicle page's spawn step (turn to face up at start; a turtlesim's only).
    spawn_step: bool
    # The relay's own video preview.
    preview: bool
    rosbridge: str
    # Whether the page's token goes to ``rosbridge`` (only to this server's own).
    rosbridge_auth: bool
    # Why ``rosbridge`` cannot be used from this page, or None.
    rosbridge_error: str | None
    # The fallback when the robot's rosapi cannot name its types.
    ros: RosSetting
    ros_types: RosConfig
    # The simulated arena the client draws instead of turtlesim's terrain; None: no arena.
    arena_map: ArenaMap | None
    robot: RobotConfig
    # Why the robot asked for (``?robot=``) cannot be driven, or None.
    robot_error: str | None
    protocol: PageProtocol


@dataclass(frozen=True)
class BaseConfig:
    """The config of a page with no role (index, parity): the protocol alone."""

    protocol: PageProtocol


@cache
def page_protocol() -> PageProtocol:
    """The protocol every page gets (built once; never mutated)."""
    return PageProtocol(
        roles=ROLES,
        default_room=DEFAULT_ROOM,
        profiles=ProfileNames(relay=relay_profiles.PROFILES, vehicle=tuple(VEHICLE_PROFILES)),
        default_profile=relay_profiles.DEFAULT_PROFILE,
        relay_profiles={
            name: RelayPacing(relay_profiles.RELAY_SNAPSHOT_PERIOD_MS[name])
            for name in relay_profiles.PROFILES
        },
        channels=ChannelLabels(AUTOPILOT_CHANNEL, AUTOPILOT_STATE_CHANNEL, CONTROL_CHANNEL),
        state_channel_options=StateChannelOptions(
            STATE_CHANNEL_ORDERED, STATE_CHANNEL_MAX_RETRANSMITS
        ),
        goal_freshness=GoalFreshness(
            GOAL_MAX_AGE_S,
            GOAL_AGE_WINDOW_S,
            GOAL_MAX_CLOCK_SKEW_S,
            GOAL_SEQ_RATE_HZ,
            GOAL_SEQ_BURST,
        ),
        video=VideoSize(*VIDEO_SIZE),
        client_forward_scale_down=CLIENT_FORWARD_SCALE_DOWN,
        frame_tag=LAYOUT,
        lock=LockRule(),
        health=HEALTH,
        opencv_build=RELAY_OPENCV_BUILD,
        schemas=Verbatim(channel_schemas()),
    )
