"""The rosbridge v2 protocol, without any I/O, over any simulated robot.

A :class:`Hub` is one simulated robot as rosbridge shows it -- its topics, its services and
rosapi's answers about its graph -- with every open :class:`RosbridgeSession` (one per WebSocket
connection). The adapter parses each text frame once (:func:`parse_frame`: a typed operation, or
a :class:`Refused` saying why it is none) and hands it to :meth:`RosbridgeSession.handle`, which
returns the direct replies (``service_response`` and ``status``); after each simulator step it
calls :meth:`Hub.tick`, and when a client's socket is ready for more it sends what
:meth:`RosbridgeSession.take_frames` returns (``publish`` messages for subscribed topics: JSON
text, a ``uint8[]`` in base64, or CBOR binary frames, a ``uint8[]`` a byte string, for a
subscription that asks ``compression: "cbor"``, as rosbridge_server sends them).
A robot is a subclass of :class:`Hub`: turtlesim's turtles (:mod:`app.turtlesim.rosbridge`), the
differential-drive robot in its room (:mod:`app.diffdrive.rosbridge`).

Behaviour follows ``rosbridge_server``: topic and service names with or without the leading
slash, replies that echo the client's spelling and ``id``, subscriptions with ``throttle_rate``
(ms) and ``queue_length``. A hub serves one ROS flavour (:mod:`app.protocol.ros`): its type
names in rosapi's answers, and only its spellings accepted in ``advertise`` and ``subscribe``
(``type`` is checked when given, never required; ``call_service``'s ``type`` is not checked, as
rosbridge does not). A failed call gets ``service_response`` with ``result: false`` and the
reason in ``values``. A request that is well formed but cannot be served gets a ``status`` only
after the client's ``set_level``, since current rosbridge_suite sends none; a frame that is no
rosbridge message at all (not JSON, no string ``op``, an unknown op, a field of the wrong type,
a published message that is not of its topic's type) always gets a ``status`` error, unless the
client asked for ``none``. rosapi's services are
answered by :class:`app.rosbridge.rosapi.RosGraph`. Besides the robot's own topics, every hub
carries topics of the types a robot description names between its clients
(:mod:`app.rosbridge.hosted`).
"""

from __future__ import annotations

import logging
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field
from typing import Annotated, Any, Final, Generic, Literal, TypeVar, get_args

import cbor2
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictInt,
    StrictStr,
    TypeAdapter,
    ValidationError,
)

from app.protocol import jsonedge
from app.protocol.errors import describe
from app.protocol.ros import RosTypes, spellings
from app.rosbridge.hosted import (
    HostedTopic,
    HostedTopics,
    HostingError,
    MalformedMessage,
    Versioned,
)
from app.rosbridge.rosapi import RosapiError, RosGraph

log = logging.getLogger(__name__)

Json = dict[str, Any]
MessageId = StrictStr | StrictInt | None
# One WebSocket frame as sent: JSON text, or CBOR bytes.
Frame = str | bytes
_Model = TypeVar("_Model", bound=BaseModel)

# Status levels by rank: after set_level a session receives statuses at or above its level;
# "none" silences them all. Before set_level it receives none.
_LEVELS = {"info": 0, "warning": 1, "error": 2, "none": 3}

# Per-session caps, so one client cannot make the server's work or memory grow without bound:
# subscriptions (topic and id pairs) and advertisements, each subscription's queue, and its
# throttle (one minute between messages is already far slower than any real subscriber wants).
# Each pose subscription of a client that reads costs a message every 16 ms tick.
MAX_SUBSCRIPTIONS: Final = 16
# Publications one client is sent per second at most, across its subscriptions (two topics at
# turtlesim's full rate); more subscriptions take turns at it, each given the latest of its topic.
# So what the clients subscribe to cannot add up to more than the server can send beside its tick.
MAX_PUBLICATIONS_PER_S: Final = 125.0
MAX_ADVERTISEMENTS: Final = 64
MAX_QUEUE_LENGTH: Final = 100
MAX_THROTTLE_RATE_MS: Final = 60_000


class ProtocolError(Exception):
    """A message that cannot be served; becomes a ``status`` error naming the problem."""


# -- operations ----------------------------------------------------------------------------


class _Op(BaseModel):
    # rosbridge messages carry optional fields we do not use (fragment_size, latch, ...).
    model_config = ConfigDict(extra="allow")

    id: MessageId = None


class Advertise(_Op):
    """``advertise``: the client will publish on ``topic``."""

    op: Literal["advertise"]
    topic: StrictStr
    type: StrictStr | None = None


class Unadvertise(_Op):
    """``unadvertise``: the client stops publishing on ``topic``."""

    op: Literal["unadvertise"]
    topic: StrictStr


class Publish(_Op):
    """``publish``: one message on ``topic``."""

    op: Literal["publish"]
    topic: StrictStr
    msg: dict[str, Any]


class Subscribe(_Op):
    """``subscribe``: send ``topic``'s messages, at most one per ``throttle_rate`` ms."""

    op: Literal["subscribe"]
    topic: StrictStr
    type: StrictStr | None = None
    throttle_rate: float = Field(
        default=0, ge=0, le=MAX_THROTTLE_RATE_MS, strict=True, allow_inf_nan=False
    )
    queue_length: StrictInt = Field(default=0, ge=0, le=MAX_QUEUE_LENGTH)
    compression: Literal["none", "cbor"] | None = None


class Unsubscribe(_Op):
    """``unsubscribe``: drop the subscription with this ``id``, or all on ``topic``."""

    op: Literal["unsubscribe"]
    topic: StrictStr


class CallService(_Op):
    """``call_service``: call ``service`` with ``args``; answered by ``service_response``."""

    op: Literal["call_service"]
    service: StrictStr
    args: dict[str, Any] = Field(default_factory=dict)
    type: StrictStr | None = None


class SetLevel(_Op):
    """``set_level``: which ``status`` messages this client receives."""

    op: Literal["set_level"]
    level: Literal["info", "warning", "error", "none"]


class Auth(_Op):
    """``auth``: the client proves a token (``token``; roslib.js's ``authenticate()`` sends it
    as ``mac``). Checked by the server's gate (``app/server/access.py``), not by the session."""

    op: Literal["auth"]
    token: StrictStr | None = None
    mac: StrictStr | None = None

    @property
    def proof(self) -> str | None:
        """The token this message carries, whichever field holds it."""
        return self.token if self.token is not None else self.mac


Operation = Annotated[
    Advertise | Unadvertise | Publish | Subscribe | Unsubscribe | CallService | SetLevel | Auth,
    Field(discriminator="op"),
]
OPS: frozenset[str] = frozenset(
    get_args(model.model_fields["op"].annotation)[0]  # each model's one Literal value
    for model in get_args(get_args(Operation)[0])
)
_operation_adapter: TypeAdapter[Operation] = TypeAdapter(Operation)


@dataclass(frozen=True)
class Refused:
    """A frame that is not a rosbridge message this server serves; ``id`` is its id, if any."""

    reason: str
    id: MessageId = None


def parse_frame(text: str) -> Operation | Refused:
    """Parse and validate one text frame; whatever it holds, a :class:`Refused` says why not.

    The one parse of a ``/rosbridge`` frame: the server's gate and the session both read the
    operation it returns.
    """
    try:
        message = jsonedge.loads(text)
    except jsonedge.JsonEdgeError as exc:
        return Refused(str(exc))
    if not isinstance(message, dict):
        return Refused("a rosbridge message must be a JSON object")
    raw_id = message.get("id")
    op_id = raw_id if isinstance(raw_id, str | int) and not isinstance(raw_id, bool) else None
    op = message.get("op")
    if not isinstance(op, str):
        return Refused("message has no string 'op' field", op_id)
    if op not in OPS:
        return Refused(f"unknown op {op!r}", op_id)
    try:
        return _operation_adapter.validate_python(message)
    except ValidationError as exc:
        # The first element of loc is the union tag (the op); the rest is the field.
        return Refused(f"{op}: {describe(exc, skip=1)}", op_id)


def service_path(service: str) -> str:
    """A service's name as this server looks it up: ``/rosapi/topics`` and ``rosapi/topics``
    are both ``rosapi/topics``, as rosbridge accepts either."""
    return service[1:] if service.startswith("/") else service


def status(level: str, text: str, op_id: object = None) -> Json:
    """A rosbridge ``status`` message (``id`` echoed when there is one)."""
    message: Json = {"op": "status", "level": level, "msg": text}
    if op_id is not None:
        message["id"] = op_id
    return message


# -- message payloads ---------------------------------------------------------------------------


def parse_payload(model: type[_Model], data: object, what: str = "") -> _Model:
    """Validate ``data``; a ``ProtocolError`` names every bad field, prefixed by ``what``."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = describe(exc)
        raise ProtocolError(f"{what}: {problems}" if what else problems) from None


def encode(message: Json, cbor: bool) -> Frame | None:
    """``message`` as one frame: CBOR bytes, or JSON text (``bytes`` in base64); None (logged)
    for a message that cannot be sent (NaN or Infinity in JSON)."""
    try:
        return cbor2.dumps(message) if cbor else jsonedge.dumps(message)
    except ValueError as exc:  # a bug upstream: never sent
        log.error("not sending a %r message: %s", message.get("op"), exc)
        return None


# -- subscriptions ---------------------------------------------------------------------------


@dataclass
class _Subscription:
    """A client's stream of one topic (by its spelling), shared by every subscribe ``id``.

    As in rosbridge, several ids on one topic give one stream: the smallest throttle and the
    largest queue win. The stream is pulled, not pushed: when the client's socket is ready for
    more, it takes the messages of its topic it has not had -- the latest ``queue_length`` of
    them (at least the latest one), all at once, or with a throttle the oldest of them once per
    throttle period. A client that reads slowly misses what newer messages supersede.
    """

    name: str
    topic: Hashable
    # The topic's version last delivered (or current when subscribed): only newer ones are due.
    seen: int
    # Each id's throttle (ms), queue length and whether it asked for CBOR.
    by_id: dict[MessageId, tuple[float, int, bool]] = field(default_factory=dict)
    last_sent: float = -math.inf

    @property
    def throttle_s(self) -> float:
        return min(t for t, _, _ in self.by_id.values()) / 1000.0

    @property
    def queue_length(self) -> int:
        return max(q for _, q, _ in self.by_id.values())

    @property
    def cbor(self) -> bool:
        """CBOR when any id asked for it, as rosbridge_server picks one compression a topic."""
        return any(c for _, _, c in self.by_id.values())

    def take(
        self, now: float, newer: list[Versioned], room: int, out: list[tuple[Json, bool]]
    ) -> None:
        """Send what is due at time ``now`` of ``newer`` (the topic's messages since ``seen``),
        at most ``room`` messages, oldest first."""
        kept = newer[-max(1, self.queue_length) :]
        if not kept or room < 1:
            return
        if self.throttle_s == 0:
            due = kept[:room]
        elif now - self.last_sent >= self.throttle_s:
            due = kept[:1]
        else:
            return
        for _, msg in due:
            out.append(({"op": "publish", "topic": self.name, "msg": msg}, self.cbor))
        self.seen = due[-1][0]
        self.last_sent = now


# -- sessions --------------------------------------------------------------------------------


class RosbridgeSession:
    """One client connection's protocol state: subscriptions, advertisements, status level."""

    def __init__(self, hub: Hub[Any]) -> None:
        self._hub = hub
        self._subscriptions: dict[str, _Subscription] = {}
        self._advertised: set[str] = set()
        # No status messages until the client asks for them with set_level.
        self._level: int | None = None
        # The publications it may still be sent (a token bucket refilled in the hub's time),
        # and the subscription whose turn it is to be served first.
        self._allowance = float(MAX_SUBSCRIPTIONS)
        self._allowance_at = hub.now
        self._turn = 0
        self._handlers: dict[str, Callable[[Any], list[Json]]] = {
            "advertise": self._advertise,
            "unadvertise": self._unadvertise,
            "publish": self._publish,
            "subscribe": self._subscribe,
            "unsubscribe": self._unsubscribe,
            "call_service": self._call_service,
            "set_level": self._set_level,
            # The gate in front of the session checks tokens; a session alone has none to check.
            "auth": lambda _auth: [],
        }
        assert set(self._handlers) == OPS, "one handler per op"

    # -- the adapter's side -------------------------------------------------------------

    def receive(self, text: str) -> list[Json]:
        """Handle one text frame; returns the replies to send back, in order."""
        return self.handle(parse_frame(text))

    def handle(self, frame: Operation | Refused) -> list[Json]:
        """Serve one parsed frame (:func:`parse_frame`); returns the replies, in order."""
        if isinstance(frame, Refused):
            return self.refuse(frame)
        try:
            return self._handlers[frame.op](frame)
        except ProtocolError as exc:
            return self._status("error", f"{frame.op}: {exc}", frame.id)

    def refuse(self, refused: Refused) -> list[Json]:
        """The ``status`` error a malformed frame gets: sent unless the client asked for none.

        rosbridge_suite sends no statuses at all; a frame that is not a rosbridge message comes
        from no rosbridge client, so it is told why rather than met with silence.
        """
        log.debug("rosbridge frame refused: %r", refused.reason)
        if self._level == _LEVELS["none"]:
            return []
        return [status("error", refused.reason, refused.id)]

    def error(self, text: str) -> list[Json]:
        """A ``status`` error for a frame the adapter refused (binary or oversize)."""
        return self.refuse(Refused(text))

    def take_frames(self) -> list[Frame]:
        """What the subscriptions have to send now, as frames (``publish`` messages in JSON, or
        CBOR where the subscription asked): call it when the client's socket is ready for
        more. Nothing waits for a client that does not call it, so one that never reads costs
        the tick nothing; one that reads is sent at most :data:`MAX_PUBLICATIONS_PER_S`, its
        subscriptions served in turn."""
        frames = (encode(message, cbor) for message, cbor in self._take())
        return [frame for frame in frames if frame is not None]

    def take_publications(self) -> list[Json]:
        """The ``publish`` messages :meth:`take_frames` would send now, as messages."""
        return [message for message, _ in self._take()]

    def _take(self) -> list[tuple[Json, bool]]:
        now = self._hub.now
        elapsed = max(0.0, now - self._allowance_at)
        self._allowance = min(
            float(MAX_SUBSCRIPTIONS), self._allowance + elapsed * MAX_PUBLICATIONS_PER_S
        )
        self._allowance_at = now
        subs = list(self._subscriptions.values())
        if not subs:
            return []
        first = self._turn % len(subs)
        out: list[tuple[Json, bool]] = []
        served = 0
        for sub in subs[first:] + subs[:first]:
            room = int(self._allowance) - len(out)
            if room < 1:
                break
            sub.take(now, self._hub.topic_messages(sub.topic, sub.seen), room, out)
            served += 1
        self._turn = first + served
        self._allowance -= len(out)
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

    def subscribes_to(self, topic: Hashable) -> bool:
        """Whether any of this session's subscriptions is to ``topic``."""
        return any(sub.topic == topic for sub in self._subscriptions.values())

    def subscription_count(self) -> int:
        """Subscriptions held, counting each (topic, id) pair."""
        return sum(len(sub.by_id) for sub in self._subscriptions.values())

    # -- ops ----------------------------------------------------------------------------

    def _advertise(self, msg: Advertise) -> list[Json]:
        if msg.topic not in self._advertised and len(self._advertised) >= MAX_ADVERTISEMENTS:
            raise ProtocolError(f"at most {MAX_ADVERTISEMENTS} advertisements per client")
        topic = self._typed_topic(msg.topic, msg.type, "advertise")
        if not isinstance(topic, HostedTopic) and self._hub.robot_publishes(topic):
            raise ProtocolError(f"{msg.topic} is published by the simulator only")
        self._advertised.add(msg.topic)
        return []

    def _unadvertise(self, msg: Unadvertise) -> list[Json]:
        if msg.topic not in self._advertised:
            return self._status("warning", f"unadvertise: {msg.topic} was not advertised", msg.id)
        self._advertised.discard(msg.topic)
        if (hosted := self._hub.hosted.find(msg.topic)) is not None:
            self._release(hosted, "advertise", msg.topic)
        return []

    def _publish(self, msg: Publish) -> list[Json]:
        hosted = self._hub.hosted.find(msg.topic)
        if hosted is not None:
            # Another robot's topic: checked against its type, then kept for its subscribers.
            try:
                self._hub.hosted.publish(hosted, msg.msg)
            except MalformedMessage as exc:  # a field of the wrong shape: always told
                return self.refuse(Refused(f"publish: {exc}", msg.id))
            except HostingError as exc:
                raise ProtocolError(str(exc)) from None
            return []
        topic = self._hub.resolve(msg.topic)
        if self._hub.robot_publishes(topic):
            raise ProtocolError(f"{msg.topic} is published by the simulator only")
        self._hub.publish(topic, msg.topic, msg.msg)
        return []

    def _subscribe(self, msg: Subscribe) -> list[Json]:
        sub = self._subscriptions.get(msg.topic)
        known = sub is not None and msg.id in sub.by_id
        if not known and self.subscription_count() >= MAX_SUBSCRIPTIONS:
            raise ProtocolError(f"at most {MAX_SUBSCRIPTIONS} subscriptions per client")
        topic = self._typed_topic(msg.topic, msg.type, "subscribe")
        if not isinstance(topic, HostedTopic):
            self._hub.check_subscribe(topic, msg.topic)
        if sub is None:
            sub = _Subscription(msg.topic, topic, seen=self._hub.topic_version(topic))
            self._subscriptions[msg.topic] = sub
        sub.by_id[msg.id] = (msg.throttle_rate, msg.queue_length, msg.compression == "cbor")
        return []

    def _unsubscribe(self, msg: Unsubscribe) -> list[Json]:
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

    def _call_service(self, msg: CallService) -> list[Json]:
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

    def _set_level(self, msg: SetLevel) -> list[Json]:
        self._level = _LEVELS[msg.level]
        return []

    # -- helpers ------------------------------------------------------------------------

    def _typed_topic(self, name: str, type_name: str | None, op: str) -> Hashable:
        """The robot's topic ``name``, its type checked, or else a topic hosted for the clients
        (claimed for this session's ``op`` until it lets go of it)."""
        try:
            topic: Hashable = self._hub.resolve(name)
        except ProtocolError as unknown:
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
                # Both reasons: what the robot has, and why no client's topic is there.
                why = str(exc).removeprefix(f"unknown topic {absolute!r}: ")
                raise ProtocolError(f"{unknown}; {why}") from None
        canonical = self._hub.topic_type(topic)
        if type_name is not None and type_name not in spellings(self._hub.types.flavour, canonical):
            raise ProtocolError(f"{name} has type {canonical}, not {type_name!r}")
        return topic

    def _release(self, topic: Hashable, op: str, name: str) -> None:
        if isinstance(topic, HostedTopic):
            self._hub.hosted.release(topic, (self, op, name))

    def _run_service(self, msg: CallService) -> Json:
        name = service_path(msg.service)
        if name.startswith("rosapi/"):
            return self._hub.graph.call(name.removeprefix("rosapi/"), msg.args)
        return self._hub.call_service(name, msg.args)

    def _status(self, level: str, text: str, op_id: object) -> list[Json]:
        log.debug("rosbridge status %s: %s", level, text)
        if self._level is None or _LEVELS[level] < self._level:
            return []
        return [status(level, text, op_id)]


# -- the robot behind the sessions -------------------------------------------------------------


K = TypeVar("K", bound=Hashable)


class Hub(ABC, Generic[K]):
    """One simulated robot and every session talking to it; keeps the latest messages of each
    topic, which each session takes when its client is ready for them.

    A subclass names its topics (``resolve`` turns a topic name into a key of type ``K``), says
    their types, takes what clients publish and gives each topic's messages by version.
    """

    def __init__(self, graph: RosGraph) -> None:
        self.graph = graph
        self.types: RosTypes = graph.types
        self.hosted = HostedTopics(graph.flavour, MAX_QUEUE_LENGTH)
        graph.hosted = self.hosted.types
        self.sessions: set[RosbridgeSession] = set()
        # The time of the last tick (throttles are measured in it) and how many there were.
        self.now = 0.0
        self.ticks = 0

    def open_session(self) -> RosbridgeSession:
        """A new client connection."""
        session = RosbridgeSession(self)
        self.sessions.add(session)
        return session

    def tick(self, now: float) -> None:
        """Call after each simulator step, with the time of it.

        Nothing is sent from here: whatever the sessions and their subscriptions, a tick costs
        the same.
        """
        self.now = now
        self.ticks += 1

    def topic_version(self, topic: K | HostedTopic) -> int:
        """The current version of a robot's topic or a hosted one."""
        if isinstance(topic, HostedTopic):
            return self.hosted.version()
        return self.version(topic)

    def topic_messages(self, topic: K | HostedTopic, seen: int) -> list[Versioned]:
        """The messages of a robot's topic or a hosted one newer than version ``seen``."""
        if isinstance(topic, HostedTopic):
            return self.hosted.newer(topic, seen)
        return self.newer(topic, seen)

    def subscribed(self, topic: K) -> bool:
        """Whether any session subscribes to ``topic``."""
        return any(session.subscribes_to(topic) for session in self.sessions)

    @abstractmethod
    def resolve(self, name: str) -> K:
        """The topic ``name`` names (leading slash optional); ``ProtocolError`` for a topic
        this robot lacks."""

    @abstractmethod
    def topic_type(self, topic: K) -> str:
        """The topic's type, spelled as this hub's flavour spells it."""

    @abstractmethod
    def robot_publishes(self, topic: K) -> bool:
        """Whether only the robot publishes on ``topic`` (clients may not advertise it)."""

    def check_subscribe(self, topic: K, name: str) -> None:
        """``ProtocolError`` when ``topic`` (spelled ``name``) cannot be subscribed to now."""

    @abstractmethod
    def publish(self, topic: K, name: str, payload: Json) -> None:
        """A client published ``payload`` on ``topic`` (spelled ``name``): take it, or raise
        ``ProtocolError`` saying why not."""

    @abstractmethod
    def version(self, topic: K) -> int:
        """The topic's current version: a new subscription takes only what comes after it."""

    @abstractmethod
    def newer(self, topic: K, seen: int) -> list[Versioned]:
        """The topic's messages newer than version ``seen``, oldest first."""

    @abstractmethod
    def call_service(self, name: str, args: Json) -> Json:
        """Call the robot's service ``name`` (no leading slash; rosapi's are answered before);
        ``ProtocolError``, ``KeyError`` or ``ValueError`` for a call that fails."""
