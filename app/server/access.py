"""Who may do what on ``/rosbridge`` and ``/turtlesim/state``, decided by room/role tokens.

Sans-I/O: the adapter hands over the handshake's token (an ``Authorization: Bearer`` header) and
each text frame, and gets back whether to pass the frame on to the rosbridge session, a reply to
send, and whether to close. A connection proves itself with its first message: the rosbridge
``auth`` op (``{"op": "auth", "token": T}``; roslib.js's ``authenticate()`` puts it in ``mac``) or
any op carrying a ``token`` field. A vehicle token may drive the simulator; a relay or client
token of any room may only read (subscribe, and the ``/rosapi`` services). With no secret
configured (development) every connection is let through.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from app.protocol import tokens
from app.protocol.close_codes import CloseCode
from app.protocol.rooms import Role
from app.protocol.tokens import Claims, TokenError

# Ops that only read the simulator; everything else (publish, advertise, services) changes it.
READ_ONLY_OPS = frozenset({"subscribe", "unsubscribe", "set_level"})
READ_ONLY_SERVICE_PREFIX = "/rosapi/"
DRIVING_ROLES: tuple[Role, ...] = ("vehicle",)
AUTH_HINT = 'authenticate first: send {"op": "auth", "token": "<token from autopilot token>"}'


def bearer_token(headers: Mapping[str, str]) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header, or None."""
    value = headers.get("authorization", "")
    scheme, _, token = value.partition(" ")
    return token.strip() or None if scheme.lower() == "bearer" else None


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

    def handshake(self, token: str | None, now: float) -> str | None:
        """Check a token sent with the handshake; returns why it is refused, or None."""
        if self.secret is None or token is None:
            return None
        try:
            self.claims = tokens.verify(self.secret, token, now=now)
        except TokenError as exc:
            return str(exc)
        return None

    def check(self, text: str, now: float) -> Decision:
        """The decision on one text frame from the client."""
        if self.secret is None:
            return Decision(forward=not _is_auth(_parse(text)))
        if self.claims is not None and self.claims.role in DRIVING_ROLES:
            return Decision(forward=True)  # a vehicle may do anything: no need to look inside
        message = _parse(text)
        if self.claims is None:
            refused = self._authenticate(message, now)
            if refused is not None:
                return refused
        return self._permit(message)

    def _permit(self, message: dict[str, Any] | None) -> Decision:
        if _is_auth(message):
            return Decision(forward=False)  # already authenticated; nothing for the session
        refusal = self._refusal(message)
        if refusal is None:
            return Decision(forward=True)
        return Decision(forward=False, reply=_status(refusal, message))

    def _authenticate(self, message: dict[str, Any] | None, now: float) -> Decision | None:
        """None once the message's token is accepted; else the refusal that ends the connection."""
        assert self.secret is not None
        token = None if message is None else message.get("token", message.get("mac"))
        if not isinstance(token, str):
            return _refuse(AUTH_HINT, message)
        try:
            self.claims = tokens.verify(self.secret, token, now=now)
        except TokenError as exc:
            return _refuse(str(exc), message)
        return None

    def _refusal(self, message: dict[str, Any] | None) -> str | None:
        assert self.claims is not None
        if self.claims.role in DRIVING_ROLES or message is None:
            return None  # a vehicle; or not JSON, which the session itself explains
        op = message.get("op")
        if op in READ_ONLY_OPS:
            return None
        service = message.get("service")
        if op == "call_service" and str(service).startswith(READ_ONLY_SERVICE_PREFIX):
            return None
        return (
            f"{op!r} changes the simulator and needs a vehicle token; "
            f"this connection has a {self.claims.role} token"
        )


def state_refusal(secret: str | None, token: str | None, now: float) -> str | None:
    """Why ``GET /turtlesim/state`` is refused to a request with ``token``, or None."""
    if secret is None:
        return None
    if token is None:
        return "send a token of any role: Authorization: Bearer <token>"
    try:
        tokens.verify(secret, token, now=now)
    except TokenError as exc:
        return str(exc)
    return None


def _parse(text: str) -> dict[str, Any] | None:
    try:
        message = json.loads(text)
    except (ValueError, RecursionError):
        return None
    return message if isinstance(message, dict) else None


def _is_auth(message: dict[str, Any] | None) -> bool:
    return message is not None and message.get("op") == "auth"


def _status(text: str, message: dict[str, Any] | None) -> dict[str, Any]:
    status: dict[str, Any] = {"op": "status", "level": "error", "msg": text}
    op_id = None if message is None else message.get("id")
    if isinstance(op_id, str | int) and not isinstance(op_id, bool):
        status["id"] = op_id
    return status


def _refuse(text: str, message: dict[str, Any] | None) -> Decision:
    return Decision(
        forward=False,
        reply=_status(text, message),
        close=(CloseCode.POLICY_VIOLATION, "token refused"),
    )
