"""The rosbridge v2 protocol over a :class:`TurtleSim`, without any I/O.

A :class:`RosbridgeHub` holds the simulator and every open :class:`RosbridgeSession` (one per
WebSocket connection). The adapter hands each received text frame to
:meth:`RosbridgeSession.receive`, which returns the direct replies (``service_response``,
``status``); after each simulator step it calls :meth:`RosbridgeHub.tick` and sends what
:meth:`RosbridgeSession.take_publications` returns (``publish`` messages for subscribed topics).

Behaviour follows ``rosbridge_server``: topic and service names with or without the leading
slash, replies that echo the client's spelling and ``id``, subscriptions with ``throttle_rate``
(ms) and ``queue_length``, ``status`` messages filtered by ``set_level``, and ROS 1 or ROS 2 type
names (``geometry_msgs/Twist`` or ``geometry_msgs/msg/Twist``). ``type`` is checked when given,
never required.
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Any, Literal, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictInt,
    StrictStr,
    ValidationError,
    field_validator,
)

from app.protocol.errors import describe
from app.turtlesim.sim import TurtleSim

log = logging.getLogger(__name__)

Json = dict[str, Any]
MessageId = StrictStr | StrictInt | None
_Model = TypeVar("_Model", bound=BaseModel)

# Status levels by rank: a session receives statuses at or above its level (rosbridge default
# "error"); "none" silences them all.
_LEVELS = {"info": 0, "warning": 1, "error": 2, "none": 3}

TWIST_TYPES = frozenset({"geometry_msgs/Twist", "geometry_msgs/msg/Twist"})
POSE_TYPES = frozenset({"turtlesim/Pose", "turtlesim/msg/Pose"})
_TOPIC_TYPES = {"cmd_vel": TWIST_TYPES, "pose": POSE_TYPES}
_TOPIC_RE = re.compile(r"/?(?P<turtle>[A-Za-z][A-Za-z0-9_]*)/(?P<leaf>cmd_vel|pose)\Z")
_SERVICE_RE = re.compile(
    r"/?(?:(?P<turtle>[A-Za-z][A-Za-z0-9_]*)/(?P<turtle_service>teleport_absolute|"
    r"teleport_relative|set_pen)|(?P<global_service>spawn|kill|reset|clear|"
    r"rosapi/topics|rosapi/services|rosapi/topic_type))\Z"
)


def _ros_types(package: str, name: str, kind: str) -> frozenset[str]:
    return frozenset({f"{package}/{name}", f"{package}/{kind}/{name}"})


class ProtocolError(Exception):
    """A message that cannot be served; becomes a ``status`` error naming the problem."""


# -- operations ----------------------------------------------------------------------------


class _Op(BaseModel):
    # rosbridge messages carry optional fields we do not use (fragment_size, latch, ...).
    model_config = ConfigDict(extra="allow")

    op: StrictStr
    id: MessageId = None


class Advertise(_Op):
    """``advertise``: the client will publish on ``topic``."""

    topic: StrictStr
    type: StrictStr | None = None


class Unadvertise(_Op):
    """``unadvertise``: the client stops publishing on ``topic``."""

    topic: StrictStr


class Publish(_Op):
    """``publish``: one message on ``topic``."""

    topic: StrictStr
    msg: dict[str, Any]


class Subscribe(_Op):
    """``subscribe``: send ``topic``'s messages, at most one per ``throttle_rate`` ms."""

    topic: StrictStr
    type: StrictStr | None = None
    throttle_rate: float = Field(default=0, ge=0, strict=True)
    queue_length: StrictInt = Field(default=0, ge=0)
    compression: Literal["none"] | None = None


class Unsubscribe(_Op):
    """``unsubscribe``: drop the subscription with this ``id``, or all on ``topic``."""

    topic: StrictStr


class CallService(_Op):
    """``call_service``: call ``service`` with ``args``; answered by ``service_response``."""

    service: StrictStr
    args: dict[str, Any] = Field(default_factory=dict)
    type: StrictStr | None = None


class SetLevel(_Op):
    """``set_level``: which ``status`` messages this client receives."""

    level: Literal["info", "warning", "error", "none"]


# -- message and service payloads ----------------------------------------------------------


class _Payload(BaseModel):
    # Unknown fields are an error, as in rosbridge; numbers must be finite JSON numbers.
    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class Vector3(_Payload):
    """``geometry_msgs/Vector3``; missing fields default to 0 as rosbridge fills them."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


class Twist(_Payload):
    """``geometry_msgs/Twist``."""

    linear: Vector3 = Field(default_factory=Vector3)
    angular: Vector3 = Field(default_factory=Vector3)


class SpawnArgs(_Payload):
    """``turtlesim/Spawn`` request."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    name: StrictStr = ""


class KillArgs(_Payload):
    """``turtlesim/Kill`` request."""

    name: StrictStr = ""


class EmptyArgs(_Payload):
    """``std_srvs/Empty`` request."""


class TeleportAbsoluteArgs(_Payload):
    """``turtlesim/TeleportAbsolute`` request."""

    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0


class TeleportRelativeArgs(_Payload):
    """``turtlesim/TeleportRelative`` request."""

    linear: float = 0.0
    angular: float = 0.0


Uint8 = Annotated[StrictInt, Field(ge=0, le=255)]


class SetPenArgs(_Payload):
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


def _parse(model: type[_Model], data: object, what: str = "") -> _Model:
    """Validate ``data``; a ``ProtocolError`` names every bad field, prefixed by ``what``."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = describe(exc)
        raise ProtocolError(f"{what}: {problems}" if what else problems) from None


def _reject_constant(name: str) -> object:
    raise ValueError(f"{name} is not valid JSON")


# -- services --------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Service:
    types: frozenset[str]
    call: Callable[[TurtleSim, str, Json], Json]


def _spawn(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    a = _parse(SpawnArgs, args, "args")
    return {"name": sim.spawn(a.x, a.y, a.theta, a.name)}


def _kill(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    sim.kill(_parse(KillArgs, args, "args").name)
    return {}


def _reset(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    _parse(EmptyArgs, args, "args")
    sim.reset()
    return {}


def _clear(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    _parse(EmptyArgs, args, "args")
    sim.clear()
    return {}


def _teleport_absolute(sim: TurtleSim, turtle: str, args: Json) -> Json:
    a = _parse(TeleportAbsoluteArgs, args, "args")
    sim.teleport_absolute(turtle, a.x, a.y, a.theta)
    return {}


def _teleport_relative(sim: TurtleSim, turtle: str, args: Json) -> Json:
    a = _parse(TeleportRelativeArgs, args, "args")
    sim.teleport_relative(turtle, a.linear, a.angular)
    return {}


def _set_pen(sim: TurtleSim, turtle: str, args: Json) -> Json:
    a = _parse(SetPenArgs, args, "args")
    sim.set_pen(turtle, a.r, a.g, a.b, a.width, bool(a.off))
    return {}


class TopicTypeArgs(_Payload):
    """``rosapi/TopicType`` request."""

    topic: StrictStr = ""


# What ``rosapi`` reports; ROS 2 names, as a ROS 2 rosbridge would.
_REPORTED_TOPIC_TYPES = {"cmd_vel": "geometry_msgs/msg/Twist", "pose": "turtlesim/msg/Pose"}
_TURTLE_SERVICES = ("teleport_absolute", "teleport_relative", "set_pen")


def _rosapi_topics(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    _parse(EmptyArgs, args, "args")
    pairs = [
        (f"/{name}/{leaf}", kind)
        for name in sim.names()
        for leaf, kind in _REPORTED_TOPIC_TYPES.items()
    ]
    return {"topics": [t for t, _ in pairs], "types": [k for _, k in pairs]}


def _rosapi_services(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    _parse(EmptyArgs, args, "args")
    names = [f"/{name}" for name in SERVICES if name not in _TURTLE_SERVICES]
    names += [f"/{turtle}/{name}" for turtle in sim.names() for name in _TURTLE_SERVICES]
    return {"services": names}


def _rosapi_topic_type(sim: TurtleSim, _turtle: str, args: Json) -> Json:
    name = _parse(TopicTypeArgs, args, "args").topic
    match = _TOPIC_RE.match(name)
    if match is None or match["turtle"] not in sim.names():
        return {"type": ""}  # rosapi's answer for a topic nobody publishes
    return {"type": _REPORTED_TOPIC_TYPES[match["leaf"]]}


def _rosapi_types(name: str) -> frozenset[str]:
    return _ros_types("rosapi", name, "srv") | _ros_types("rosapi_msgs", name, "srv")


_EMPTY_TYPES = _ros_types("std_srvs", "Empty", "srv")
SERVICES: dict[str, _Service] = {
    "spawn": _Service(_ros_types("turtlesim", "Spawn", "srv"), _spawn),
    "kill": _Service(_ros_types("turtlesim", "Kill", "srv"), _kill),
    "reset": _Service(_EMPTY_TYPES, _reset),
    "clear": _Service(_EMPTY_TYPES, _clear),
    "teleport_absolute": _Service(
        _ros_types("turtlesim", "TeleportAbsolute", "srv"), _teleport_absolute
    ),
    "teleport_relative": _Service(
        _ros_types("turtlesim", "TeleportRelative", "srv"), _teleport_relative
    ),
    "set_pen": _Service(_ros_types("turtlesim", "SetPen", "srv"), _set_pen),
    # The discovery services of rosbridge_suite's rosapi node, which clients' get_topics() use.
    "rosapi/topics": _Service(_rosapi_types("Topics"), _rosapi_topics),
    "rosapi/services": _Service(_rosapi_types("Services"), _rosapi_services),
    "rosapi/topic_type": _Service(_rosapi_types("TopicType"), _rosapi_topic_type),
}


# -- topics ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Topic:
    """A resolved topic: which turtle, and ``cmd_vel`` or ``pose``."""

    turtle: str
    leaf: Literal["cmd_vel", "pose"]

    @property
    def types(self) -> frozenset[str]:
        """Type names a client may give for this topic."""
        return _TOPIC_TYPES[self.leaf]


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
    """A ``turtlesim/Pose`` message for one turtle."""
    p = sim.pose(turtle)
    return {
        "x": p.x,
        "y": p.y,
        "theta": p.theta,
        "linear_velocity": p.linear_velocity,
        "angular_velocity": p.angular_velocity,
    }


# -- subscriptions ---------------------------------------------------------------------------


@dataclass
class _Subscription:
    """A client's stream of one topic (by its spelling), shared by every subscribe ``id``.

    As in rosbridge, several ids on one topic give one stream: the smallest throttle and the
    largest queue win. With a throttle and no queue a message is sent when the throttle allows
    and dropped otherwise; with a queue the latest ``queue_length`` messages wait and one leaves
    per throttle period.
    """

    name: str
    topic: Topic
    by_id: dict[MessageId, tuple[float, int]] = field(default_factory=dict)
    queue: deque[Json] = field(default_factory=deque)
    last_sent: float = -math.inf

    @property
    def throttle_s(self) -> float:
        return min(t for t, _ in self.by_id.values()) / 1000.0

    @property
    def queue_length(self) -> int:
        return max(q for _, q in self.by_id.values())

    def offer(self, now: float, msg: Json, out: list[Json]) -> None:
        """A new message on the topic at time ``now``."""
        throttle = self.throttle_s
        if throttle == 0:
            self._send(now, msg, out)
        elif self.queue_length == 0:
            if now - self.last_sent >= throttle:
                self._send(now, msg, out)
        else:
            self.queue.append(msg)
            while len(self.queue) > self.queue_length:
                self.queue.popleft()

    def drain(self, now: float, out: list[Json]) -> None:
        """Send a queued message if the throttle period is over."""
        if self.queue and now - self.last_sent >= self.throttle_s:
            self._send(now, self.queue.popleft(), out)

    def _send(self, now: float, msg: Json, out: list[Json]) -> None:
        self.last_sent = now
        out.append({"op": "publish", "topic": self.name, "msg": msg})


# -- sessions --------------------------------------------------------------------------------


class RosbridgeSession:
    """One client connection's protocol state: subscriptions, advertisements, status level."""

    def __init__(self, hub: RosbridgeHub) -> None:
        self._hub = hub
        self._subscriptions: dict[str, _Subscription] = {}
        self._advertised: set[str] = set()
        self._level = _LEVELS["error"]
        self._outbox: list[Json] = []
        self._handlers: dict[str, Callable[[Json], list[Json]]] = {
            "advertise": self._advertise,
            "unadvertise": self._unadvertise,
            "publish": self._publish,
            "subscribe": self._subscribe,
            "unsubscribe": self._unsubscribe,
            "call_service": self._call_service,
            "set_level": self._set_level,
        }

    # -- the adapter's side -------------------------------------------------------------

    def receive(self, text: str) -> list[Json]:
        """Handle one text frame; returns the replies to send back, in order."""
        try:
            message = json.loads(text, parse_constant=_reject_constant)
        except ValueError as exc:
            return self._status("error", f"malformed JSON: {exc}", None)
        except RecursionError:
            return self._status("error", "malformed JSON: nested too deeply", None)
        if not isinstance(message, dict):
            return self._status("error", "a rosbridge message must be a JSON object", None)
        raw_id = message.get("id")
        op_id = raw_id if isinstance(raw_id, str | int) and not isinstance(raw_id, bool) else None
        op = message.get("op")
        if not isinstance(op, str):
            return self._status("error", "message has no string 'op' field", op_id)
        handler = self._handlers.get(op)
        if handler is None:
            return self._status("error", f"unknown op {op!r}", op_id)
        try:
            return handler(message)
        except ProtocolError as exc:
            return self._status("error", f"{op}: {exc}", op_id)

    def error(self, text: str) -> list[Json]:
        """A ``status`` error for a problem the adapter found (binary or oversize frame)."""
        return self._status("error", text, None)

    def take_publications(self) -> list[Json]:
        """Publications gathered since the last call (from ticks and other clients' messages)."""
        out, self._outbox = self._outbox, []
        return out

    def close(self) -> None:
        """Forget this client's subscriptions and advertisements."""
        self._subscriptions.clear()
        self._advertised.clear()
        self._hub.sessions.discard(self)

    def subscribed_topics(self) -> list[str]:
        """Topic names (as the client spelled them) this session receives."""
        return list(self._subscriptions)

    # -- hub's side ---------------------------------------------------------------------

    def deliver(self, now: float, topic: Topic, msg: Json) -> None:
        """Offer a message on ``topic`` to every matching subscription of this session."""
        for sub in self._subscriptions.values():
            if sub.topic == topic:
                sub.offer(now, msg, self._outbox)

    def drain(self, now: float) -> None:
        """Release queued messages whose throttle period is over."""
        for sub in self._subscriptions.values():
            sub.drain(now, self._outbox)

    # -- ops ----------------------------------------------------------------------------

    def _advertise(self, message: Json) -> list[Json]:
        msg = _parse(Advertise, message)
        topic = self._typed_topic(msg.topic, msg.type)
        if topic.leaf == "pose":
            raise ProtocolError(f"{msg.topic} is published by the simulator only")
        self._advertised.add(msg.topic)
        return []

    def _unadvertise(self, message: Json) -> list[Json]:
        msg = _parse(Unadvertise, message)
        if msg.topic not in self._advertised:
            return self._status("warning", f"unadvertise: {msg.topic} was not advertised", msg.id)
        self._advertised.discard(msg.topic)
        return []

    def _publish(self, message: Json) -> list[Json]:
        msg = _parse(Publish, message)
        topic = resolve_topic(msg.topic)
        if topic.leaf == "pose":
            raise ProtocolError(f"{msg.topic} is published by the simulator only")
        twist = _parse(Twist, msg.msg, f"{msg.topic} (geometry_msgs/Twist)")
        try:
            self._hub.sim.cmd_vel(topic.turtle, twist.linear.x, twist.angular.z)
        except KeyError:
            raise ProtocolError(f"no turtle named {topic.turtle!r} for {msg.topic}") from None
        self._hub.broadcast(topic, twist.model_dump())
        return []

    def _subscribe(self, message: Json) -> list[Json]:
        msg = _parse(Subscribe, message)
        topic = self._typed_topic(msg.topic, msg.type)
        if topic.leaf == "pose" and topic.turtle not in self._hub.sim.names():
            raise ProtocolError(f"unknown topic {msg.topic!r}: no turtle named {topic.turtle!r}")
        sub = self._subscriptions.setdefault(msg.topic, _Subscription(msg.topic, topic))
        sub.by_id[msg.id] = (msg.throttle_rate, msg.queue_length)
        return []

    def _unsubscribe(self, message: Json) -> list[Json]:
        msg = _parse(Unsubscribe, message)
        sub = self._subscriptions.get(msg.topic)
        if sub is None or (msg.id is not None and msg.id not in sub.by_id):
            return self._status("warning", f"unsubscribe: not subscribed to {msg.topic}", msg.id)
        if msg.id is None:
            sub.by_id.clear()
        else:
            del sub.by_id[msg.id]
        if not sub.by_id:
            del self._subscriptions[msg.topic]
        return []

    def _call_service(self, message: Json) -> list[Json]:
        msg = _parse(CallService, message)
        reply: Json = {"op": "service_response", "service": msg.service}
        if msg.id is not None:
            reply["id"] = msg.id
        try:
            values = self._run_service(msg)
        except (ProtocolError, KeyError, ValueError) as exc:
            # rosbridge answers a failed call with result false (roslibpy's errback gets the
            # text) and reports it as a status error too.
            text = exc.args[0] if exc.args else str(exc)
            failure = {**reply, "values": f"{msg.service}: {text}", "result": False}
            return [*self._status("error", f"call_service {msg.service}: {text}", msg.id), failure]
        return [{**reply, "values": values, "result": True}]

    def _set_level(self, message: Json) -> list[Json]:
        self._level = _LEVELS[_parse(SetLevel, message).level]
        return []

    # -- helpers ------------------------------------------------------------------------

    def _typed_topic(self, name: str, type_name: str | None) -> Topic:
        topic = resolve_topic(name)
        if type_name is not None and type_name not in topic.types:
            raise ProtocolError(f"{name} has type {sorted(topic.types)[0]}, not {type_name!r}")
        return topic

    def _run_service(self, msg: CallService) -> Json:
        match = _SERVICE_RE.match(msg.service)
        if match is None:
            raise ProtocolError("unknown service")
        turtle = match["turtle"] or ""
        service = SERVICES[match["turtle_service"] or match["global_service"]]
        if msg.type is not None and msg.type not in service.types:
            raise ProtocolError(f"has type {sorted(service.types)[0]}, not {msg.type!r}")
        return service.call(self._hub.sim, turtle, msg.args)

    def _status(self, level: str, text: str, op_id: object) -> list[Json]:
        log.debug("rosbridge status %s: %s", level, text)
        if _LEVELS[level] < self._level:
            return []
        status: Json = {"op": "status", "level": level, "msg": text}
        if op_id is not None:
            status["id"] = op_id
        return [status]


class RosbridgeHub:
    """The simulator and every session talking to it; fans messages out to subscribers."""

    def __init__(self, sim: TurtleSim) -> None:
        self.sim = sim
        self.sessions: set[RosbridgeSession] = set()
        self._now = -math.inf

    def open_session(self) -> RosbridgeSession:
        """A new client connection."""
        session = RosbridgeSession(self)
        self.sessions.add(session)
        return session

    def tick(self, now: float) -> None:
        """Call after each simulator step: offers every turtle's pose to its subscribers."""
        self._now = now
        poses = {name: pose_message(self.sim, name) for name in self.sim.names()}
        for session in self.sessions:
            for name, msg in poses.items():
                session.deliver(now, Topic(name, "pose"), msg)
            session.drain(now)

    def broadcast(self, topic: Topic, msg: Json) -> None:
        """A client published ``msg``: every session subscribed to ``topic`` gets it."""
        for session in self.sessions:
            session.deliver(self._now, topic, msg)
