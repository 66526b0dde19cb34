"""Sans-I/O signaling hub: rooms, roles and relay rules, with no sockets in it.

The rules are those of docs/architecture.md, "Signaling protocol".

The transport calls :meth:`Hub.connect` for each new connection, :meth:`Hub.receive` for each
text frame and :meth:`Hub.disconnect` when the socket goes away. Each returns the actions to
carry out, in order: :class:`Outgoing` messages to deliver and :class:`Close` for connections to
shut. The hub never blocks and never touches the network, so every rule is testable directly.
"""

from __future__ import annotations

import itertools
import logging
import shlex
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Final, Literal, Protocol, assert_never

from app.protocol import tokens
from app.protocol.close_codes import CloseCode
from app.protocol.jsonedge import oversize
from app.protocol.rooms import Role
from app.protocol.signaling import (
    INCOMING_TYPES,
    Answer,
    Candidate,
    Error,
    GetOps,
    IceServer,
    IceTransportPolicy,
    Incoming,
    Leave,
    Login,
    LoginReply,
    Offer,
    ParseError,
    PeerInfo,
    Peers,
    Renew,
    Renewed,
    Start,
    Stop,
    parse,
)

log = logging.getLogger(__name__)

ConnId = str

# Places in a room, by role: each role has its own, so clients never take the relay's or the
# vehicle's. One relay and one vehicle (a second of either is refused by name, see _login).
ROOM_PLACES: Final[Mapping[Role, int]] = {"vehicle": 1, "relay": 1, "client": 30}
# Peers per room. Also bounds each roster update, which every join and leave sends to everyone
# in the room (N messages of N entries).
MAX_ROOM_PEERS: Final = sum(ROOM_PLACES.values())
# Sessions one token may hold in its room at once (a person's few tabs), so one token handed
# around or stolen cannot take every client place.
MAX_TOKEN_SESSIONS: Final = 4
# Per-sender rate limits (token buckets): a burst of this many messages, refilled at this rate ...
# Trickled ICE candidates come in bursts of a few dozen; a client flooding ``stop`` is refused
# (and, after ``max_errors_in_a_row``, closed) before the relay it targets falls behind.
RATE_BURST: Final = 100
RATE_PER_S: Final = 50.0
# ... and a burst of this many bytes, refilled at this rate. A relay answering every client of a
# full room at once sends a few hundred KB; a sender's burst stays well inside one receiver's
# outbox (Settings.outbox_bytes, 1 MiB), so no one sender can make its receiver a slow reader.
BYTES_BURST: Final = 256 * 1024
BYTES_PER_S: Final = 64 * 1024


@dataclass(frozen=True)
class Outgoing:
    """Deliver ``message`` (a JSON object) to connection ``conn``."""

    conn: ConnId
    message: dict[str, Any]


@dataclass(frozen=True)
class Close:
    """Close connection ``conn`` once the messages queued before this action are delivered."""

    conn: ConnId
    code: int
    reason: str


Action = Outgoing | Close


# Why the server refused a connection, a login or a message: the only values of the ``reason``
# label of ``autopilot_refusals_total`` (a fixed set, so the series stay bounded whatever peers
# send). The hub decides auth, caps (a full room), rate_limit and invalid; the transport the rest.
Refusal = Literal["auth", "origin", "rate_limit", "caps", "slow_reader", "invalid"]
REFUSALS: Final[tuple[Refusal, ...]] = (
    "auth",
    "origin",
    "rate_limit",
    "caps",
    "slow_reader",
    "invalid",
)


class HubMetrics(Protocol):
    """What the hub reports as it works (:class:`app.server.metrics.ServerMetrics`)."""

    def message(self, kind: str) -> None:
        """A frame was read: its ``type`` when it is a known one, else ``"other"``."""

    def refused(self, reason: Refusal) -> None:
        """A frame or a login was refused, for ``reason``."""


@dataclass(frozen=True)
class Census:
    """Who is here: rooms with anyone in them, and peers of each role."""

    rooms: int
    peers: dict[Role, int]


@dataclass(frozen=True)
class _Peer:
    conn: ConnId
    name: str
    role: Role
    room: str
    # The grant of the token it logged in with (None without a secret): each grant's sessions
    # in a room are counted, renewed tokens included.
    grant: str | None = field(default=None, repr=False)

    def info(self) -> PeerInfo:
        return PeerInfo(name=self.name, role=self.role)


@dataclass
class _Bucket:
    """A token bucket: holds at most ``burst``, refilled at ``per_s``."""

    burst: float
    per_s: float
    checked_at: float
    level: float = field(init=False)

    def __post_init__(self) -> None:
        self.level = self.burst

    def take(self, amount: float, now: float) -> bool:
        """Take ``amount`` out at time ``now``; False (and nothing taken) when it is short."""
        self.level = min(self.burst, self.level + (now - self.checked_at) * self.per_s)
        self.checked_at = now
        if self.level < amount:
            return False
        self.level -= amount
        return True


@dataclass
class _Connection:
    id: ConnId
    messages: _Bucket
    bytes: _Bucket
    peer: _Peer | None = None
    # What the peer's token grants, while it is logged in with one; it ends with ``exp``.
    claims: tokens.Claims | None = None
    errors_in_a_row: int = 0
    closing: bool = False


@dataclass
class Hub:
    """All rooms of one server. Synchronous and single-threaded: call it from one event loop.

    ``ice(name)`` gives the ICE configuration of a successful login (the server mints TURN
    credentials there); without it logins get no ICE servers and the ``all`` policy.
    """

    # Signs the tokens a login must carry (one for its room and role); None: no tokens asked.
    secret: str | None = field(default=None, repr=False)
    ice: Callable[[str], tuple[list[IceServer], IceTransportPolicy]] | None = None
    max_message_bytes: int = 64 * 1024
    # A peer whose last this-many messages were all refused is closed as abusive.
    max_errors_in_a_row: int = 20
    _connections: dict[ConnId, _Connection] = field(default_factory=dict, init=False)
    # room -> name -> peer, in join order (rosters list peers in the order they joined).
    _rooms: dict[str, dict[str, _Peer]] = field(default_factory=dict, init=False)
    _ids: itertools.count[int] = field(default_factory=itertools.count, init=False)
    # Unix seconds, for token expiry and the senders' rate limit; tests pass their own.
    clock: Callable[[], float] = time.time
    # Told of every frame read and every refusal; None: nobody counts.
    metrics: HubMetrics | None = None

    def connect(self) -> ConnId:
        """Register a new connection and return its opaque id."""
        conn, now = f"c{next(self._ids)}", self.clock()
        self._connections[conn] = _Connection(
            conn, _Bucket(RATE_BURST, RATE_PER_S, now), _Bucket(BYTES_BURST, BYTES_PER_S, now)
        )
        return conn

    def logged_in(self, conn: ConnId) -> bool:
        """True once ``conn`` has logged in (and until it leaves)."""
        connection = self._connections.get(conn)
        return connection is not None and connection.peer is not None

    def rooms(self) -> list[str]:
        """Names of the rooms that have anyone in them."""
        return list(self._rooms)

    def census(self) -> Census:
        """How many rooms and peers of each role there are now."""
        peers: dict[Role, int] = {}
        for room in self._rooms.values():
            for peer in room.values():
                peers[peer.role] = peers.get(peer.role, 0) + 1
        return Census(len(self._rooms), peers)

    def roster(self, room: str) -> list[PeerInfo]:
        """Who is in ``room`` now, in join order."""
        return [peer.info() for peer in self._rooms.get(room, {}).values()]

    def receive(self, conn: ConnId, text: str) -> list[Action]:
        """Handle one text frame from ``conn``."""
        connection = self._connections[conn]
        size = len(text.encode("utf-8"))
        if (turned_away := self._turn_away(connection, size)) is not None:
            return turned_away
        if (too_large := oversize(text, self.max_message_bytes)) is not None:
            self._count("other")
            return self._refuse(connection, too_large, None)
        if _expired(connection, self.clock()):
            return self._expire(connection)
        message = parse(text)
        if isinstance(message, ParseError):
            self._count(message.ref if message.ref in INCOMING_TYPES else "other")
            if message.ref == "login" and connection.peer is None:
                return self._refuse_login(connection, message.reason)
            return self._refuse(connection, message.reason, message.ref)
        self._count(message.type)
        return self._dispatch(connection, message)

    def expire(self) -> list[Action]:
        """End every session whose token has expired: call it every second or so.

        Each gets an ``error`` saying so and is closed (1008 "token expired"); the others in
        its room are told it left.
        """
        now = self.clock()
        actions: list[Action] = []
        for connection in list(self._connections.values()):
            if _expired(connection, now):
                actions += self._expire(connection)
        return actions

    def claims_of(self, conn: ConnId) -> tokens.Claims | None:
        """What the token of ``conn``'s session grants (None: no token asked, or not logged in)."""
        connection = self._connections.get(conn)
        return None if connection is None else connection.claims

    def restore(self, conn: ConnId, claims: tokens.Claims) -> None:
        """Give a session rebuilt without its token (a room taken over) the claims it had, so
        that it still ends when they expire."""
        self._connections[conn].claims = claims

    def receive_binary(self, conn: ConnId) -> list[Action]:
        """Handle one binary frame from ``conn``: always refused, signaling is JSON text."""
        connection = self._connections[conn]
        if (turned_away := self._turn_away(connection, 0)) is not None:
            return turned_away
        self._count("other")
        return self._refuse(connection, "binary frames are not accepted; send JSON text", None)

    def disconnect(self, conn: ConnId) -> list[Action]:
        """The socket of ``conn`` is gone: a closed socket counts as ``leave``."""
        connection = self._connections.pop(conn, None)
        if connection is None or connection.peer is None:
            return []
        return self._remove(connection.peer)

    # -- dispatch -------------------------------------------------------------------------------

    def _turn_away(self, connection: _Connection, size: int) -> list[Action] | None:
        """What a frame of ``size`` bytes gets before it is read: nothing while closing, a
        refusal over the sender's message or byte rate. None when the frame may be read.

        Refused before parsing: a flood costs its sender, never the peer it targets.
        """
        if connection.closing:
            return []
        now = self.clock()
        if not connection.messages.take(1, now):
            limit = f"more than {RATE_PER_S:g} messages per second"
        elif not connection.bytes.take(size, now):
            limit = f"more than {BYTES_PER_S // 1024} KiB per second"
        else:
            return None
        return self._refuse(connection, f"rate limit: {limit}", None, why="rate_limit")

    def _dispatch(self, connection: _Connection, message: Incoming) -> list[Action]:
        peer = connection.peer
        if isinstance(message, Login):
            if peer is not None:
                return self._refuse(
                    connection,
                    f"already logged in as {peer.name!r} in room {peer.room!r}",
                    "login",
                )
            return self._login(connection, message)
        if peer is None:
            return self._refuse(connection, "log in first", message.type)
        match message:
            case Offer():
                actions = self._relay_to(peer, message, message.to, ("vehicle", "client"))
            case Answer():
                actions = self._relay_to(peer, message, message.to, ("relay",))
            case Candidate():
                actions = self._relay_to(peer, message, message.to, ("vehicle", "relay", "client"))
            case Start() | Stop() | GetOps():
                actions = self._to_relay(peer, message)
            case Leave():
                actions = self._leave(connection, peer)
            case Renew():
                actions = self._renew(connection, peer, message)
            case _:
                assert_never(message)
        if isinstance(actions, str):
            return self._refuse(connection, actions, message.type)
        connection.errors_in_a_row = 0
        return actions

    def _login(self, connection: _Connection, login: Login) -> list[Action]:
        claims: tokens.Claims | None = None
        if self.secret is not None:
            checked = _login_claims(self.secret, login, self.clock())
            if isinstance(checked, str):
                return self._refuse_login(connection, checked, why="auth")
            claims = checked
        # Only a successful login creates a room: refused ones must not leave empty rooms behind.
        room = self._rooms.get(login.room, {})
        if login.name in room:
            return self._refuse_login(
                connection, f"name {login.name!r} is already taken in room {login.room!r}"
            )
        # One relay and one vehicle per room: the relay pilots one vehicle and forwards one
        # video. A second of either is told at the door which one the room has, rather than
        # admitted to take the first one's place at the relay.
        if login.role in ("relay", "vehicle"):
            holder = _one_of(room, login.role)
            if holder is not None:
                return self._refuse_login(
                    connection,
                    f"room {login.room!r} already has a {login.role} ({holder.name!r})",
                )
        grant = None if claims is None else claims.grant
        if (no_place := _no_place(room, login, grant)) is not None:
            return self._refuse_login(connection, no_place, why="caps")
        others = list(room.values())
        peer = _Peer(connection.id, login.name, login.role, login.room, grant)
        self._rooms.setdefault(login.room, room)[peer.name] = peer
        connection.peer = peer
        connection.claims = claims
        connection.errors_in_a_row = 0
        log.info("%s %r joined room %r", peer.role, peer.name, peer.room)
        ice_servers, policy = self.ice(peer.name) if self.ice is not None else ([], "all")
        reply = LoginReply(
            success=True,
            room=peer.room,
            peers=[p.info() for p in others],
            iceServers=ice_servers,
            iceTransportPolicy=policy,
            renewIn=None if claims is None else claims.renew_in(self.clock()),
        )
        # The others learn about the newcomer from their roster update.
        return [
            Outgoing(connection.id, reply.model_dump(exclude_none=True)),
            *self._rosters(peer.room, skip=connection.id),
        ]

    def _relay_to(
        self, sender: _Peer, message: Offer | Answer | Candidate, to: str, roles: tuple[Role, ...]
    ) -> list[Action] | str:
        if sender.role not in roles:
            return (
                f"{message.type} may only be sent by {' or '.join(roles)}, not by a {sender.role}"
            )
        target = self._rooms[sender.room].get(to)
        if target is None:
            return f"no peer named {to!r} in room {sender.room!r}"
        if target is sender:
            return f"cannot send {message.type} to yourself"
        log.debug(
            "relaying %s from %r to %r in room %r", message.type, sender.name, to, sender.room
        )
        return [Outgoing(target.conn, _stamped(message, sender))]

    def _to_relay(self, sender: _Peer, message: Start | Stop | GetOps) -> list[Action] | str:
        if sender.role != "client":
            return f"{message.type} may only be sent by a client, not by a {sender.role}"
        relay = _relay_of(self._rooms[sender.room])
        if relay is None:
            return f"no relay in room {sender.room!r}"
        log.debug("relaying %s from %r to relay %r", message.type, sender.name, relay.name)
        return [Outgoing(relay.conn, _stamped(message, sender))]

    def _renew(self, connection: _Connection, peer: _Peer, renew: Renew) -> list[Action] | str:
        """Extend the session: with the token the peer brings, else with one minted here."""
        if self.secret is None or connection.claims is None:
            return "this server asks for no tokens: there is nothing to renew"
        now = self.clock()
        token = renew.token
        try:
            if token is None:
                token = tokens.renewal(self.secret, connection.claims, now=now)
            claims = tokens.verify(self.secret, token, now=now, room=peer.room, roles=(peer.role,))
        except (tokens.TokenError, ValueError) as exc:
            return f"cannot renew: {exc}; {_remedy(peer.room, peer.role, 'get a new one')}"
        connection.claims = claims
        log.debug("%s %r renewed its token until %d", peer.role, peer.name, claims.exp)
        reply = Renewed(token=token, renewIn=claims.renew_in(now))
        return [Outgoing(connection.id, reply.model_dump())]

    def _expire(self, connection: _Connection) -> list[Action]:
        """End a session whose token has expired: the reason, the others told, the close."""
        peer = connection.peer
        assert peer is not None
        if self.metrics is not None:
            self.metrics.refused("auth")
        log.info("%s %r in room %r: token expired", peer.role, peer.name, peer.room)
        reason = (
            "token expired: renew before it does (send renew); "
            f"{_remedy(peer.room, peer.role, 'get a new one')}"
        )
        connection.closing = True
        connection.peer = connection.claims = None
        return [
            Outgoing(connection.id, Error(reason=reason, ref=None).model_dump()),
            *self._remove(peer),
            Close(connection.id, CloseCode.POLICY_VIOLATION, "token expired"),
        ]

    def _leave(self, connection: _Connection, peer: _Peer) -> list[Action]:
        connection.closing = True
        connection.peer = None
        return [*self._remove(peer), Close(connection.id, CloseCode.NORMAL, "left")]

    # -- helpers --------------------------------------------------------------------------------

    def _remove(self, peer: _Peer) -> list[Action]:
        """Take ``peer`` out of its room and tell the others (``leave`` then a roster update)."""
        room = self._rooms[peer.room]
        del room[peer.name]
        log.info("%s %r left room %r", peer.role, peer.name, peer.room)
        if not room:
            del self._rooms[peer.room]
            return []
        left = {"type": "leave", "from": peer.name}
        return [Outgoing(other.conn, dict(left)) for other in room.values()] + self._rosters(
            peer.room
        )

    def _rosters(self, room_name: str, *, skip: ConnId | None = None) -> list[Action]:
        """A ``peers`` message to everyone in the room, each listing the others."""
        room = self._rooms[room_name]
        # Each entry is built once; each recipient's roster is then a filtered list of them
        # (N rosters of N-1 entries remain, bounded by MAX_ROOM_PEERS).
        entries = [(peer, peer.info()) for peer in room.values()]
        actions: list[Action] = []
        for recipient in room.values():
            if recipient.conn == skip:
                continue
            others = [info for peer, info in entries if peer is not recipient]
            actions.append(
                Outgoing(recipient.conn, Peers(room=room_name, peers=others).model_dump())
            )
        return actions

    def _count(self, kind: str) -> None:
        if self.metrics is not None:
            self.metrics.message(kind)

    def _refuse(
        self, connection: _Connection, reason: str, ref: str | None, why: Refusal = "invalid"
    ) -> list[Action]:
        """An ``error`` reply; closes the connection after too many refusals in a row.

        ``why`` is the refusal's kind for the metrics; anything not a token, a cap or the rate
        limit is a message the protocol does not allow.
        """
        if self.metrics is not None:
            self.metrics.refused(why)
        actions: list[Action] = [
            Outgoing(connection.id, Error(reason=reason, ref=ref).model_dump())
        ]
        connection.errors_in_a_row += 1
        if connection.errors_in_a_row >= self.max_errors_in_a_row:
            who = repr(connection.peer.name) if connection.peer else f"connection {connection.id}"
            log.warning("closing %s: %d bad messages in a row", who, connection.errors_in_a_row)
            connection.closing = True
            if connection.peer is not None:
                actions += self._remove(connection.peer)
                connection.peer = None
            actions.append(
                Close(
                    connection.id,
                    CloseCode.POLICY_VIOLATION,
                    f"abusive: {connection.errors_in_a_row} bad messages in a row",
                )
            )
        else:
            # %r: both may quote what the peer sent, and must not forge a log line.
            log.debug("refused %r from %s: %r", ref, connection.id, reason)
        return actions

    def _refuse_login(
        self, connection: _Connection, reason: str, why: Refusal = "invalid"
    ) -> list[Action]:
        """A failed login reply, followed by the ``error`` every refused message gets."""
        reply = LoginReply(success=False, reason=reason).model_dump(exclude_none=True)
        return [Outgoing(connection.id, reply), *self._refuse(connection, reason, "login", why)]


def _expired(connection: _Connection, now: float) -> bool:
    """True when ``connection``'s session holds a token that has expired by ``now``."""
    return (
        connection.peer is not None
        and connection.claims is not None
        and connection.claims.exp <= now
    )


def _no_place(room: dict[str, _Peer], login: Login, grant: str | None) -> str | None:
    """Why ``login`` finds no place in ``room`` (its role's places are taken, or its token's
    grant's sessions), in words; None when it may join."""
    places = ROOM_PLACES[login.role]
    if sum(peer.role == login.role for peer in room.values()) >= places:
        return f"room {login.room!r} has no place for another {login.role} ({places})"
    if grant is not None:
        sessions = sum(peer.grant == grant for peer in room.values())
        if sessions >= MAX_TOKEN_SESSIONS:
            return (
                f"this token already has {sessions} sessions in room {login.room!r}, the most "
                "one token may hold: close one, or get a token of your own"
            )
    return None


def _one_of(room: dict[str, _Peer], role: Role) -> _Peer | None:
    return next((peer for peer in room.values() if peer.role == role), None)


def _relay_of(room: dict[str, _Peer]) -> _Peer | None:
    return _one_of(room, "relay")


def _stamped(message: Incoming, sender: _Peer) -> dict[str, Any]:
    """The message as the peer sent it (extra fields included), with the server's ``from``."""
    return {**message.model_dump(), "from": sender.name}


def _remedy(room: str, role: Role, what: str = "get one") -> str:
    """How to get a token for ``role`` in ``room``: whoever runs the server mints them, so the
    words name the command, for a page or a log."""
    return f"{what} with: autopilot token --room {shlex.quote(room)} --role {role}"


def _login_claims(secret: str, login: Login, now: float) -> tokens.Claims | str:
    """What ``login``'s token grants; or why it may not join (no token, or one not for its
    room and role) and how to get one that will."""
    if login.token is None:
        return (
            f"missing token: a {login.role} token for room {login.room!r} is required; "
            f"{_remedy(login.room, login.role)}"
        )
    try:
        return tokens.verify(secret, login.token, now=now, room=login.room, roles=(login.role,))
    except tokens.TokenError as exc:
        return f"{exc}; {_remedy(login.room, login.role, 'get a new one')}"
