"""turtlesim as rosbridge shows it: a :class:`~app.rosbridge.protocol.Hub` over a
:class:`TurtleSim`, without any I/O.

Each turtle has ``/<turtle>/cmd_vel`` (``geometry_msgs/Twist``: clients publish, and subscribers
get what is published) and ``/<turtle>/pose`` (``turtlesim/Pose``, a new one every tick), and the
services turtlesim has (``spawn``, ``kill``, ``reset``, ``clear``, and each turtle's
``set_pen``, ``teleport_absolute``, ``teleport_relative``). The rest of the protocol -- sessions,
subscriptions, rosapi -- is :mod:`app.rosbridge`'s.
"""

from __future__ import annotations

import re
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import Field, StrictInt, StrictStr, field_validator

from app.protocol.ros import DEFAULT_FLAVOUR, RosFlavour
from app.rosbridge.hosted import Versioned
from app.rosbridge.messages import Payload, Twist
from app.rosbridge.protocol import (
    MAX_QUEUE_LENGTH,
    Hub,
    ProtocolError,
    parse_payload,
)
from app.rosbridge.rosapi import RosGraph
from app.turtlesim.rosapi import GLOBAL_SERVICES, TURTLE_SERVICES, TurtlesimNode
from app.turtlesim.sim import MAX_TURTLES, TurtleSim, float32

Json = dict[str, Any]

_TOPIC_RE = re.compile(r"/?(?P<turtle>[A-Za-z][A-Za-z0-9_]*)/(?P<leaf>cmd_vel|pose)\Z")
_TURTLE_SERVICE_RE = re.compile(r"/?(?P<turtle>[A-Za-z][A-Za-z0-9_]*)/(?P<leaf>[a-z_]+)\Z")


# -- service payloads ------------------------------------------------------------------------


class SpawnArgs(Payload):
    """``turtlesim/Spawn`` request."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    name: StrictStr = ""


class KillArgs(Payload):
    """``turtlesim/Kill`` request."""

    name: StrictStr = ""


class EmptyArgs(Payload):
    """``std_srvs/Empty`` request."""


class TeleportAbsoluteArgs(Payload):
    """``turtlesim/TeleportAbsolute`` request."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


class TeleportRelativeArgs(Payload):
    """``turtlesim/TeleportRelative`` request."""

    linear: float = 0.0
    angular: float = 0.0


Uint8 = Annotated[StrictInt, Field(ge=0, le=255)]


class SetPenArgs(Payload):
    """``turtlesim/SetPen`` request (``off`` is a uint8 in the .srv; a bool is accepted too)."""

    r: Uint8 = 0
    g: Uint8 = 0
    b: Uint8 = 0
    width: Uint8 = 0
    off: Uint8 = 0

    @field_validator("off", mode="before")
    @classmethod
    def _bool_is_uint8(cls, value: object) -> object:
        return int(value) if isinstance(value, bool) else value


# -- services --------------------------------------------------------------------------------


_ServiceCall = Callable[[TurtleSim, str, Json], Json]


def _spawn(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    a = parse_payload(SpawnArgs, args, "args")
    return {"name": sim.spawn(a.x, a.y, a.theta, a.name)}


def _kill(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    sim.kill(parse_payload(KillArgs, args, "args").name)
    return {}


def _reset(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    parse_payload(EmptyArgs, args, "args")
    sim.reset()
    return {}


def _clear(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    parse_payload(EmptyArgs, args, "args")
    sim.clear()
    return {}


def _teleport_absolute(sim: TurtleSim, turtle: str, args: Json) -> Json:
    a = parse_payload(TeleportAbsoluteArgs, args, "args")
    sim.teleport_absolute(turtle, a.x, a.y, a.theta)
    return {}


def _teleport_relative(sim: TurtleSim, turtle: str, args: Json) -> Json:
    a = parse_payload(TeleportRelativeArgs, args, "args")
    sim.teleport_relative(turtle, a.linear, a.angular)
    return {}


def _set_pen(sim: TurtleSim, turtle: str, args: Json) -> Json:
    a = parse_payload(SetPenArgs, args, "args")
    sim.set_pen(turtle, a.r, a.g, a.b, a.width, bool(a.off))
    return {}


# turtlesim's services by name; a turtle's own services get its name as the second argument.
SERVICES: dict[str, _ServiceCall] = {
    "spawn": _spawn,
    "kill": _kill,
    "reset": _reset,
    "clear": _clear,
    "teleport_absolute": _teleport_absolute,
    "teleport_relative": _teleport_relative,
    "set_pen": _set_pen,
}
assert set(SERVICES) == {*GLOBAL_SERVICES, *TURTLE_SERVICES}, "the graph lists what is served"


# -- topics ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Topic:
    """A resolved topic: which turtle, and ``cmd_vel`` or ``pose``."""

    turtle: str
    leaf: Literal["cmd_vel", "pose"]


def resolve_topic(name: str) -> Topic:
    """Resolve a topic name (leading slash optional); ``ProtocolError`` for a topic we lack."""
    match = _TOPIC_RE.match(name)
    if match is None:
        raise ProtocolError(
            f"unknown topic {name!r}: this simulator has /<turtle>/cmd_vel and /<turtle>/pose"
        )
    leaf: Literal["cmd_vel", "pose"] = "pose" if match["leaf"] == "pose" else "cmd_vel"
    return Topic(match["turtle"], leaf)


def pose_message(sim: TurtleSim, turtle: str) -> Json:
    """A ``turtlesim/Pose`` message for one turtle; its fields are float32, as on the wire."""
    p = sim.pose(turtle)
    return {
        "x": float32(p.x),
        "y": float32(p.y),
        "theta": float32(p.theta),
        "linear_velocity": float32(p.linear_velocity),
        "angular_velocity": float32(p.angular_velocity),
    }


# -- the hub ---------------------------------------------------------------------------------


class RosbridgeHub(Hub[Topic]):
    """turtlesim and every session talking to it."""

    def __init__(
        self,
        sim: TurtleSim,
        ros: RosFlavour = DEFAULT_FLAVOUR,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        super().__init__(RosGraph(TurtlesimNode(sim), ros, wall_clock))
        self.sim = sim
        # The turtlesim_msgs-era node (Jazzy) moves sideways only once its parameter says so.
        sim.holonomic = ros != "jazzy"
        self._poses: dict[str, Json] = {}  # this tick's, made when first asked for
        # Each turtle's latest Twists as published, with the version each was given.
        self._twists: dict[str, deque[Versioned]] = {}
        self._twist_version = 0

    def tick(self, now: float) -> None:
        """Call after each simulator step: a new pose of every turtle, as of ``now``."""
        super().tick(now)
        self._poses.clear()

    # -- the protocol's questions ----------------------------------------------------------

    def resolve(self, name: str) -> Topic:
        """``/<turtle>/cmd_vel`` or ``/<turtle>/pose`` (leading slash optional)."""
        return resolve_topic(name)

    def topic_type(self, topic: Topic) -> str:
        """``geometry_msgs/Twist`` or ``turtlesim/Pose``, as this hub's flavour spells it."""
        return self.types.twist if topic.leaf == "cmd_vel" else self.types.pose

    def robot_publishes(self, topic: Topic) -> bool:
        """Poses come from the simulator only."""
        return topic.leaf == "pose"

    def check_subscribe(self, topic: Topic, name: str) -> None:
        """A pose needs its turtle alive (a cmd_vel may be listened to before it is spawned)."""
        if topic.leaf == "pose" and topic.turtle not in self.sim.names():
            raise ProtocolError(f"unknown topic {name!r}: no turtle named {topic.turtle!r}")

    def publish(self, topic: Topic, name: str, payload: Json) -> None:
        """A Twist on a turtle's cmd_vel: the turtle drives it, its subscribers get it."""
        twist = parse_payload(Twist, payload, f"{name} (geometry_msgs/Twist)")
        try:
            self.sim.cmd_vel(topic.turtle, twist.linear.x, twist.angular.z, twist.linear.y)
        except KeyError:
            raise ProtocolError(f"no turtle named {topic.turtle!r} for {name}") from None
        self.broadcast(topic, twist.model_dump())

    def broadcast(self, topic: Topic, msg: Json) -> None:
        """A client published ``msg`` on a ``cmd_vel`` topic: its subscribers take it next."""
        if topic.turtle not in self._twists and len(self._twists) >= MAX_TURTLES:
            living = set(self.sim.names())  # forget the Twists of turtles killed since
            self._twists = {name: q for name, q in self._twists.items() if name in living}
        self._twist_version += 1
        queue = self._twists.setdefault(topic.turtle, deque(maxlen=MAX_QUEUE_LENGTH))
        queue.append((self._twist_version, msg))

    def version(self, topic: Topic) -> int:
        """Every tick is a new version of every pose topic; every Twist of the cmd_vel ones."""
        return self.ticks if topic.leaf == "pose" else self._twist_version

    def newer(self, topic: Topic, seen: int) -> list[Versioned]:
        """The topic's messages newer than version ``seen``, oldest first: a pose topic has
        only its latest (a newer pose supersedes the older ones)."""
        if topic.leaf == "cmd_vel":
            return [item for item in self._twists.get(topic.turtle, ()) if item[0] > seen]
        if self.ticks <= seen:
            return []
        pose = self._poses.get(topic.turtle)
        if pose is None:
            try:
                pose = self._poses[topic.turtle] = pose_message(self.sim, topic.turtle)
            except KeyError:  # killed: its subscribers get nothing until one is spawned again
                return []
        return [(self.ticks, pose)]

    def call_service(self, name: str, args: Json) -> Json:
        """turtlesim's services: the global ones, and ``<turtle>/<service>``."""
        if name in GLOBAL_SERVICES:
            return SERVICES[name](self.sim, "", args)
        match = _TURTLE_SERVICE_RE.match(name)
        if match is None or match["leaf"] not in TURTLE_SERVICES:
            raise ProtocolError("unknown service")
        return SERVICES[match["leaf"]](self.sim, match["turtle"], args)
