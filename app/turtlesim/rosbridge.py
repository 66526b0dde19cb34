"""The rosbridge v2 protocol over a :class:`TurtleSim`, without any I/O.

A :class:`RosbridgeHub` holds the simulator and every open :class:`RosbridgeSession` (one per
WebSocket connection). The adapter hands each received text frame to
:meth:`RosbridgeSession.receive`, which returns the direct replies (``service_response``, and
``status`` for a client that asked for them); after each simulator step it calls
:meth:`RosbridgeHub.tick` and sends what :meth:`RosbridgeSession.take_publications` returns
(``publish`` messages for subscribed topics).

Behaviour follows ``rosbridge_server``: topic and service names with or without the leading
slash, replies that echo the client's spelling and ``id``, subscriptions with ``throttle_rate``
(ms) and ``queue_length``. A hub serves one ROS flavour (:mod:`app.protocol.ros`): its type
names in rosapi's answers, and only its spellings accepted in ``advertise`` and ``subscribe``
(``type`` is checked when given, never required; ``call_service``'s ``type`` is not checked, as
rosbridge does not). A failed call gets ``service_response`` with ``result: false`` and the
reason in ``values``; ``status`` messages are sent only after the client's ``set_level``, since
current rosbridge_suite sends none. rosapi's services are answered by
:class:`app.turtlesim.rosapi.RosGraph`. Besides the turtles' topics, the hub carries topics of
the types a robot description names between its clients (:mod:`app.turtlesim.hosted`).
"""

from __future__ import annotations

import logging
import math
import re
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Any, Final, Literal, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictInt,
    StrictStr,
    ValidationError,
    field_validator,
)

from app.protocol import jsonedge
from app.protocol.errors import describe
from app.protocol.ros import DEFAULT_FLAVOUR, RosFlavour, RosTypes, spellings
from app.turtlesim.hosted import HostedTopic, HostedTopics, HostingError
from app.turtlesim.messages import Payload as _Payload
from app.turtlesim.messages import Twist
from app.turtlesim.rosapi import (
    GLOBAL_SERVICES,
    TURTLE_SERVICES,
    RosapiError,
    RosGraph,
)
from app.turtlesim.sim import TurtleSim, float32

log = logging.getLogger(__name__)

Json = dict[str, Any]
MessageId = StrictStr | StrictInt | None
_Model = TypeVar("_Model", bound=BaseModel)

# Status levels by rank: after set_level a session receives statuses at or above its level;
# "none" silences them all. Before set_level it receives none.
_LEVELS = {"info": 0, "warning": 1, "error": 2, "none": 3}

# Per-session caps, so one client cannot make every tick slower or its memory grow without bound:
# subscriptions (topic and id pairs) and advertisements, each subscription's queue, and its
# throttle (one minute between messages is already far slower than any real subscriber wants).
# Each pose subscription costs a message every 16 ms tick: with 64, one hostile client spawning
# 2000 turtles pushed /healthz p50 to 77 ms on a loaded 2-core machine; with 16, 19 ms.
MAX_SUBSCRIPTIONS: Final = 16
MAX_ADVERTISEMENTS: Final = 64
MAX_QUEUE_LENGTH: Final = 100
MAX_THROTTLE_RATE_MS: Final = 60_000

_TOPIC_RE = re.compile(r"/?(?P<turtle>[A-Za-z][A-Za-z0-9_]*)/(?P<leaf>cmd_vel|pose)\Z")
_TURTLE_SERVICE_RE = re.compile(r"/?(?P<turtle>[A-Za-z][A-Za-z0-9_]*)/(?P<leaf>[a-z_]+)\Z")


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
    throttle_rate: float = Field(
        default=0, ge=0, le=MAX_THROTTLE_RATE_MS, strict=True, allow_inf_nan=False
    )
    queue_length: StrictInt = Field(default=0, ge=0, le=MAX_QUEUE_LENGTH)
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


# -- services --------------------------------------------------------------------------------


_ServiceCall = Callable[[TurtleSim, str, Json], Json]


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
    topic: Topic | HostedTopic
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
        # No status messages until the client asks for them with set_level.
        self._level: int | None = None
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
            message = jsonedge.loads(text)
        except jsonedge.JsonEdgeError as exc:
            return self._status("error", str(exc), None)
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
        for name, sub in self._subscriptions.items():
            self._release(sub.topic, "subscribe", name)
        for name in self._advertised:
            if (hosted := self._hub.hosted.find(name)) is not None:
                self._release(hosted, "advertise", name)
        self._subscriptions.clear()
        self._advertised.clear()
        self._hub.sessions.discard(self)

    def subscribed_topics(self) -> list[str]:
        """Topic names (as the client spelled them) this session receives."""
        return list(self._subscriptions)

    def subscription_count(self) -> int:
        """Subscriptions held, counting each (topic, id) pair."""
        return sum(len(sub.by_id) for sub in self._subscriptions.values())

    # -- hub's side ---------------------------------------------------------------------

    def deliver(self, now: float, topic: Topic | HostedTopic, msg: Json) -> None:
        """Offer a message on ``topic`` to every matching subscription of this session."""
        for sub in self._subscriptions.values():
            if sub.topic == topic:
                sub.offer(now, msg, self._outbox)

    def deliver_poses(self, now: float, pose_of: Callable[[str], Json | None]) -> None:
        """Offer each subscribed turtle's pose: work per tick grows with the subscriptions,
        not with turtles times subscriptions."""
        for sub in self._subscriptions.values():
            topic = sub.topic
            if isinstance(topic, Topic) and topic.leaf == "pose":
                if (msg := pose_of(topic.turtle)) is not None:
                    sub.offer(now, msg, self._outbox)

    def drain(self, now: float) -> None:
        """Release queued messages whose throttle period is over."""
        for sub in self._subscriptions.values():
            sub.drain(now, self._outbox)

    # -- ops ----------------------------------------------------------------------------

    def _advertise(self, message: Json) -> list[Json]:
        msg = _parse(Advertise, message)
        if msg.topic not in self._advertised and len(self._advertised) >= MAX_ADVERTISEMENTS:
            raise ProtocolError(f"at most {MAX_ADVERTISEMENTS} advertisements per client")
        topic = self._typed_topic(msg.topic, msg.type, "advertise")
        if isinstance(topic, Topic) and topic.leaf == "pose":
            raise ProtocolError(f"{msg.topic} is published by the simulator only")
        self._advertised.add(msg.topic)
        return []

    def _unadvertise(self, message: Json) -> list[Json]:
        msg = _parse(Unadvertise, message)
        if msg.topic not in self._advertised:
            return self._status("warning", f"unadvertise: {msg.topic} was not advertised", msg.id)
        self._advertised.discard(msg.topic)
        if (hosted := self._hub.hosted.find(msg.topic)) is not None:
            self._release(hosted, "advertise", msg.topic)
        return []

    def _publish(self, message: Json) -> list[Json]:
        msg = _parse(Publish, message)
        hosted = self._hub.hosted.find(msg.topic)
        if hosted is not None:
            # Another robot's topic: checked against its type, then to its subscribers.
            try:
                self._hub.broadcast(hosted, self._hub.hosted.message(hosted, msg.msg))
            except HostingError as exc:
                raise ProtocolError(str(exc)) from None
            return []
        topic = resolve_topic(msg.topic)
        if topic.leaf == "pose":
            raise ProtocolError(f"{msg.topic} is published by the simulator only")
        twist = _parse(Twist, msg.msg, f"{msg.topic} (geometry_msgs/Twist)")
        try:
            self._hub.sim.cmd_vel(topic.turtle, twist.linear.x, twist.angular.z, twist.linear.y)
        except KeyError:
            raise ProtocolError(f"no turtle named {topic.turtle!r} for {msg.topic}") from None
        self._hub.broadcast(topic, twist.model_dump())
        return []

    def _subscribe(self, message: Json) -> list[Json]:
        msg = _parse(Subscribe, message)
        sub = self._subscriptions.get(msg.topic)
        known = sub is not None and msg.id in sub.by_id
        if not known and self.subscription_count() >= MAX_SUBSCRIPTIONS:
            raise ProtocolError(f"at most {MAX_SUBSCRIPTIONS} subscriptions per client")
        topic = self._typed_topic(msg.topic, msg.type, "subscribe")
        if (
            isinstance(topic, Topic)
            and topic.leaf == "pose"
            and topic.turtle not in self._hub.sim.names()
        ):
            raise ProtocolError(f"unknown topic {msg.topic!r}: no turtle named {topic.turtle!r}")
        if sub is None:
            sub = self._subscriptions[msg.topic] = _Subscription(msg.topic, topic)
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
            self._release(sub.topic, "subscribe", msg.topic)
        return []

    def _call_service(self, message: Json) -> list[Json]:
        msg = _parse(CallService, message)
        reply: Json = {"op": "service_response", "service": msg.service}
        if msg.id is not None:
            reply["id"] = msg.id
        try:
            values = self._run_service(msg)
        except (ProtocolError, RosapiError, KeyError, ValueError) as exc:
            # rosbridge answers a failed call with result false (roslibpy's errback gets the
            # text); a status error goes only to a client that asked for statuses.
            text = exc.args[0] if exc.args else str(exc)
            failure = {**reply, "values": f"{msg.service}: {text}", "result": False}
            return [*self._status("error", f"call_service {msg.service}: {text}", msg.id), failure]
        return [{**reply, "values": values, "result": True}]

    def _set_level(self, message: Json) -> list[Json]:
        self._level = _LEVELS[_parse(SetLevel, message).level]
        return []

    # -- helpers ------------------------------------------------------------------------

    def _typed_topic(self, name: str, type_name: str | None, op: str) -> Topic | HostedTopic:
        try:
            topic = resolve_topic(name)
        except ProtocolError:
            absolute = name if name.startswith("/") else f"/{name}"
            hosted = self._hub.hosted
            if absolute in self._hub.graph.topics() and hosted.find(absolute) is None:
                raise ProtocolError(
                    f"{name} is on a real robot's graph, but this simulator publishes nothing "
                    "on it and takes nothing from it"
                ) from None
            try:
                return hosted.claim(name, type_name, (self, op, name))
            except HostingError as exc:
                raise ProtocolError(str(exc)) from None
        types = self._hub.types
        canonical = types.twist if topic.leaf == "cmd_vel" else types.pose
        if type_name is not None and type_name not in spellings(types.flavour, canonical):
            raise ProtocolError(f"{name} has type {canonical}, not {type_name!r}")
        return topic

    def _release(self, topic: Topic | HostedTopic, op: str, name: str) -> None:
        if isinstance(topic, HostedTopic):
            self._hub.hosted.release(topic, (self, op, name))

    def _run_service(self, msg: CallService) -> Json:
        name = msg.service[1:] if msg.service.startswith("/") else msg.service
        if name.startswith("rosapi/"):
            return self._hub.graph.call(name.removeprefix("rosapi/"), msg.args)
        if name in GLOBAL_SERVICES:
            return SERVICES[name](self._hub.sim, "", msg.args)
        match = _TURTLE_SERVICE_RE.match(name)
        if match is None or match["leaf"] not in TURTLE_SERVICES:
            raise ProtocolError("unknown service")
        return SERVICES[match["leaf"]](self._hub.sim, match["turtle"], msg.args)

    def _status(self, level: str, text: str, op_id: object) -> list[Json]:
        log.debug("rosbridge status %s: %s", level, text)
        if self._level is None or _LEVELS[level] < self._level:
            return []
        status: Json = {"op": "status", "level": level, "msg": text}
        if op_id is not None:
            status["id"] = op_id
        return [status]


class RosbridgeHub:
    """The simulator and every session talking to it; fans messages out to subscribers."""

    def __init__(
        self,
        sim: TurtleSim,
        ros: RosFlavour = DEFAULT_FLAVOUR,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        self.sim = sim
        self.hosted = HostedTopics(ros)
        self.graph = RosGraph(sim, ros, wall_clock, self.hosted.types)
        self.types: RosTypes = self.graph.types
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
        living = set(self.sim.names())
        poses: dict[str, Json] = {}

        def pose_of(name: str) -> Json | None:
            if name not in living:
                return None
            if name not in poses:
                poses[name] = pose_message(self.sim, name)
            return poses[name]

        for session in self.sessions:
            session.deliver_poses(now, pose_of)
            session.drain(now)

    def broadcast(self, topic: Topic | HostedTopic, msg: Json) -> None:
        """A client published ``msg``: every session subscribed to ``topic`` gets it."""
        for session in self.sessions:
            session.deliver(self._now, topic, msg)
