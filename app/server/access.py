"""Who may do what on ``/rosbridge`` and the simulated robot's state route, decided by room/role
tokens.

Sans-I/O: the adapter hands over the handshake's token (an ``Authorization: Bearer`` header) and
each frame, parsed once (:func:`app.rosbridge.protocol.parse_frame`), and gets back whether to
pass the frame on to the rosbridge session, a reply to send, and whether to close. A connection
proves itself with its first message: the rosbridge ``auth`` op (``{"op": "auth", "token": T}``;
roslib.js's ``authenticate()`` puts it in ``mac``) or any op carrying a ``token`` field. The
connection ends when its token expires (status error, close 1008 "token expired") unless it sends
``auth`` again with a fresh token before then.

What each role may do is an allow-list, :data:`ROSBRIDGE_RIGHTS`: a vehicle token drives; a
relay or client token only reads -- it may subscribe and call rosapi's reading services, and
nothing that publishes, changes the simulator or sets a parameter. Which robot a token reaches
is the server's: one robot for every room, or one per room, when the adapter binds a connection
to its token's room (:meth:`RosbridgeGate.bind`), after which only a token of that room renews
it. With no secret configured (development) every
connection is let through.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final

from app.protocol import tokens
from app.protocol.close_codes import CloseCode
from app.protocol.tokens import Claims, TokenError, TokenRole
from app.rosbridge.protocol import (
    OPS,
    Auth,
    CallService,
    Operation,
    Refused,
    service_path,
    status,
)
from app.rosbridge.rosapi import ROSAPI_READS


@dataclass(frozen=True)
class Rights:
    """What a token's role may do on ``/rosbridge``: these ops, and ``call_service`` on these
    services (named as :func:`~app.rosbridge.protocol.service_path` names them; None: any)."""

    ops: frozenset[str]
    services: frozenset[str] | None

    def allows(self, operation: Operation) -> bool:
        """True when ``operation`` is among these rights."""
        if operation.op not in self.ops:
            return False
        if isinstance(operation, CallService) and self.services is not None:
            return service_path(operation.service) in self.services
        return True


DRIVE = Rights(ops=OPS, services=None)
READ = Rights(
    ops=frozenset({"auth", "subscribe", "unsubscribe", "set_level", "call_service"}),
    services=frozenset(f"rosapi/{name}" for name in ROSAPI_READS),
)
# A fleet token is for the fleet view alone: verify() refuses it here, and it has no rights.
NOTHING = Rights(ops=frozenset(), services=frozenset())
ROSBRIDGE_RIGHTS: Final[Mapping[TokenRole, Rights]] = {
    "vehicle": DRIVE,
    "relay": READ,
    "client": READ,
    "fleet": NOTHING,
}
AUTH_HINT = 'authenticate first: send {"op": "auth", "token": "<token from autopilot token>"}'
EXPIRED = 'token expired: send {"op": "auth", "token": "<a fresh token>"} before it does'


@dataclass(frozen=True)
class Decision:
    """What to do with one frame: pass it on, reply, close (code and reason) or a mix."""

    forward: bool
    reply: dict[str, Any] | None = None
    close: tuple[int, str] | None = None


@dataclass
class RosbridgeGate:
    """The access state of one ``/rosbridge`` connection."""

    secret: str | None
    claims: Claims | None = field(default=None)
    # The room whose robot the connection reaches, once the adapter bound it to one.
    bound_room: str | None = field(default=None)

    def handshake(self, token: str | None, now: float) -> str | None:
        """Check a token sent with the handshake; returns why it is refused, or None."""
        if self.secret is None or token is None:
            return None
        try:
            self.claims = tokens.verify(self.secret, token, now=now)
        except TokenError as exc:
            return str(exc)
        return None

    @property
    def room(self) -> str | None:
        """The room the connection's token names; None while it has proved none."""
        return None if self.claims is None else self.claims.room

    def bind(self, room: str | None) -> None:
        """The connection now reaches ``room``'s robot (None: a robot of every room): from now
        on only a token of that room renews it."""
        self.bound_room = room

    @property
    def expires_at(self) -> float | None:
        """When the connection's token expires (Unix seconds); None while it has none."""
        return None if self.claims is None else float(self.claims.exp)

    def expiry(self, now: float) -> Decision | None:
        """The close of a connection whose token has expired by ``now`` (its token forgotten);
        else None."""
        if self.claims is None or self.claims.exp > now:
            return None
        self.claims = None
        return _refuse(EXPIRED, None, "token expired")

    def check(self, frame: Operation | Refused, now: float) -> Decision:
        """The decision on one parsed frame from the client (a malformed one included: the
        session explains it, once the connection has proved a token).

        An ``auth`` op on a connection that has proved a token renews it: the session goes on
        past the first token's expiry with the rights of the new one.
        """
        if self.secret is None:
            return Decision(forward=not isinstance(frame, Auth))
        if (expired := self.expiry(now)) is not None:
            return expired
        if self.claims is None:
            refused = self._authenticate(frame, now)
            if refused is not None:
                return refused
        elif isinstance(frame, Auth):
            return self._renew(frame, now)
        if isinstance(frame, Auth):
            return Decision(forward=False)  # authenticated; nothing for the session
        refusal = None if isinstance(frame, Refused) else self._refusal(frame)
        if refusal is None:
            return Decision(forward=True)
        return Decision(forward=False, reply=status("error", refusal, frame.id))

    def _authenticate(self, frame: Operation | Refused, now: float) -> Decision | None:
        """None once the frame's token is accepted; else the refusal that ends the connection."""
        assert self.secret is not None
        token = _token_of(frame)
        if token is None:
            return _refuse(AUTH_HINT, frame)
        try:
            self.claims = tokens.verify(self.secret, token, now=now)
        except TokenError as exc:
            return _refuse(str(exc), frame)
        return None

    def _renew(self, auth: Auth, now: float) -> Decision:
        """A new token for a connection that has one: kept if valid, else refused (the
        connection goes on with the token it has, until that expires)."""
        assert self.secret is not None
        try:
            claims = tokens.verify(self.secret, auth.proof or "", now=now)
        except TokenError as exc:
            return Decision(forward=False, reply=status("error", f"auth: {exc}", auth.id))
        if self.bound_room is not None and claims.room != self.bound_room:
            refusal = (
                f"auth: this connection reaches room {self.bound_room!r}'s robot; "
                f"a token of room {claims.room!r} cannot renew it"
            )
            return Decision(forward=False, reply=status("error", refusal, auth.id))
        self.claims = claims
        return Decision(forward=False)

    def _refusal(self, operation: Operation) -> str | None:
        assert self.claims is not None
        role = self.claims.role
        if ROSBRIDGE_RIGHTS[role].allows(operation):
            return None
        if isinstance(operation, CallService):
            what = f"call_service {operation.service!r}"
        else:
            what = repr(operation.op)
        return f"{what} needs a vehicle token: a {role} token may only read"


def bearer_claims(secret: str, token: str | None, now: float) -> Claims | str:
    """What a request's bearer ``token`` (of any role) grants, or why it is refused."""
    if token is None:
        return "send a token of any role: Authorization: Bearer <token>"
    try:
        return tokens.verify(secret, token, now=now)
    except TokenError as exc:
        return str(exc)


def _token_of(frame: Operation | Refused) -> str | None:
    """The token a frame offers: the ``auth`` op's, or a ``token`` field on any other op."""
    if isinstance(frame, Refused):
        return None
    if isinstance(frame, Auth):
        return frame.proof
    token = (frame.model_extra or {}).get("token")
    return token if isinstance(token, str) else None


def _refuse(
    text: str, frame: Operation | Refused | None, reason: str = "token refused"
) -> Decision:
    """A refusal that ends the connection: ``text`` for the client, then the close."""
    return Decision(
        forward=False,
        reply=status("error", text, None if frame is None else frame.id),
        close=(CloseCode.POLICY_VIOLATION, reason),
    )
