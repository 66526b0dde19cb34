"""The signaling messages as pydantic models, parsed once at the edge (docs/architecture.md,
"Signaling protocol").

Peers may add fields of their own (they are relayed as sent), except ``from``: the server stamps
the sender's name on everything it relays, whatever the peer wrote there.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Final, Literal, get_args

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    StringConstraints,
    TypeAdapter,
    ValidationError,
)

from app.protocol import jsonedge
from app.protocol.errors import describe
from app.protocol.rooms import DEFAULT_ROOM, Role

# Names and rooms show up in logs and on pages; keep them short, non-empty, and free of control
# characters and line separators (a name must never start a forged log line).
_UNPRINTABLE = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]")


def _printable(text: str) -> str:
    if _UNPRINTABLE.search(text):
        raise ValueError("must not contain control characters or line breaks")
    return text


Name = Annotated[str, StringConstraints(min_length=1, max_length=64), AfterValidator(_printable)]


class _Incoming(BaseModel):
    # strict: a number is not a name; extra: pages may carry fields of their own.
    model_config = ConfigDict(extra="allow", strict=True, frozen=True)


class Login(_Incoming):
    """A peer introduces itself; must be the first message on a connection."""

    type: Literal["login"]
    name: Name
    role: Role
    room: Name = DEFAULT_ROOM
    token: str | None = None


class Offer(_Incoming):
    """An SDP offer from a vehicle or client to another peer (normally the room's relay)."""

    type: Literal["offer"]
    to: Name
    sdp: str


class Answer(_Incoming):
    """An SDP answer from the relay to a vehicle or client."""

    type: Literal["answer"]
    to: Name
    sdp: str


class Candidate(_Incoming):
    """A trickled ICE candidate (RTCIceCandidateInit), or null at the end of candidates."""

    type: Literal["candidate"]
    to: Name
    candidate: dict[str, Any] | None


class Leave(_Incoming):
    """The sender leaves its room; the server tells the others and closes the connection."""

    type: Literal["leave"]


class Start(_Incoming):
    """A client asks the room's relay to start piloting."""

    type: Literal["start"]


class Stop(_Incoming):
    """A client asks the room's relay to stop piloting."""

    type: Literal["stop"]


class GetOps(_Incoming):
    """A client asks the room's relay for its list of operations."""

    type: Literal["getOps"]


class Renew(_Incoming):
    """A peer keeps its session past its token's expiry: with a fresh ``token`` of its room and
    role, or with none to be given one (:class:`Renewed`) while its current token is valid."""

    type: Literal["renew"]
    token: str | None = None


Incoming = Annotated[
    Login | Offer | Answer | Candidate | Leave | Start | Stop | GetOps | Renew,
    Field(discriminator="type"),
]
INCOMING_TYPES: frozenset[str] = frozenset(
    get_args(model.model_fields["type"].annotation)[0]  # each model's one Literal value
    for model in get_args(get_args(Incoming)[0])
)
_incoming_adapter: TypeAdapter[Incoming] = TypeAdapter(Incoming)


class PeerInfo(BaseModel):
    """One entry of a roster."""

    name: str
    role: Role


IceTransportPolicy = Literal["all", "relay"]


class IceServer(BaseModel):
    """One entry of RTCConfiguration.iceServers."""

    urls: list[str]
    username: str | None = None
    credential: str | None = None


class LoginReply(BaseModel):
    """The server's answer to ``login``: success with the room's roster, or a reason.

    A successful reply carries the peer's ICE configuration: ``iceServers`` (TURN entries with
    credentials minted for this login, valid for a limited time) and ``iceTransportPolicy``, so
    a page or an agent never holds a long-lived TURN password.
    """

    type: Literal["login"] = "login"
    success: bool
    room: str | None = None
    peers: list[PeerInfo] = Field(default_factory=list)
    reason: str | None = None
    iceServers: list[IceServer] | None = None  # noqa: N815 (the WebRTC spelling)
    iceTransportPolicy: IceTransportPolicy | None = None  # noqa: N815
    # Seconds until the peer should send ``renew``; None when the server asks for no tokens.
    renewIn: float | None = None  # noqa: N815 (the pages' spelling)


class Renewed(BaseModel):
    """The server's answer to ``renew``: the session's token now, and when to renew it next.

    The session ends when its token expires (``error`` "token expired", then close 1008).
    """

    type: Literal["renewed"] = "renewed"
    token: str
    renewIn: float  # noqa: N815


class Peers(BaseModel):
    """Roster update sent to the others in a room whenever someone joins or leaves."""

    type: Literal["peers"] = "peers"
    room: str
    peers: list[PeerInfo]


class Error(BaseModel):
    """Why the server refused a message; ``ref`` is the offending message's type, if known."""

    type: Literal["error"] = "error"
    reason: str
    ref: str | None = None


@dataclass(frozen=True)
class ParseError:
    """A text frame that is not a valid incoming message."""

    reason: str
    ref: str | None


# The largest frame of these types, in bytes of UTF-8: a trickled candidate is one line of a few
# hundred bytes and the rest carry next to nothing. Peers may add fields to any message (they are
# relayed as sent), so the frame is bounded, not only the fields the models know. Offers and
# answers carry an SDP of tens of KB and get the socket's own limit.
MAX_FRAME_BYTES: Final[Mapping[str, int]] = {
    "candidate": 4096,
    "renew": 2048,
    "leave": 1024,
    "start": 1024,
    "stop": 1024,
    "getOps": 1024,
}


def parse(text: str) -> Incoming | ParseError:
    """Parse one text frame into its message model, or say precisely why it is not one."""
    try:
        data = jsonedge.loads(text)
    except jsonedge.JsonEdgeError as exc:
        return ParseError(str(exc), None)
    if not isinstance(data, dict):
        return ParseError(f"expected a JSON object, got {type(data).__name__}", None)
    kind = data.get("type")
    if not isinstance(kind, str):
        return ParseError("missing or non-string field 'type'", None)
    if kind not in INCOMING_TYPES:
        return ParseError(f"unknown message type {kind!r}", kind)
    if kind in MAX_FRAME_BYTES:
        size, limit = len(text.encode("utf-8")), MAX_FRAME_BYTES[kind]
        if size > limit:
            return ParseError(f"{kind} message of {size} bytes exceeds its limit of {limit}", kind)
    try:
        return _incoming_adapter.validate_python(data)
    except ValidationError as exc:
        # The first element of loc is the union tag (the message type); the rest is the field.
        return ParseError(describe(exc, skip=1), kind)
