"""Short-lived credentials scoped to one room and one role, signed with ``AUTOPILOT_SECRET``.

A token is ``<payload>.<signature>``, both base64url without padding: the payload is the compact
JSON ``{"room": R, "role": ROLE, "exp": UNIX_SECONDS}`` and the signature is HMAC-SHA256 of the
encoded payload under the server's secret. Nothing here reads a clock or the environment: callers
pass ``now`` and the secret, so the rules are tested directly.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import json
import math
from collections.abc import Collection
from dataclasses import dataclass
from typing import Literal, get_args

from app.protocol.rooms import Role as Role  # re-exported: tokens.Role

ROLES: tuple[Role, ...] = get_args(Role)

# The environment variables that carry them: the server's signing secret, and the token a
# headless peer (the relay service, the vehicle agent) logs in with -- from the environment
# rather than the command line, where ``ps`` shows it.
SECRET_ENV = "AUTOPILOT_SECRET"
ACCESS_TOKEN_ENV = "AUTOPILOT_ACCESS_TOKEN"

DEFAULT_TTL_S = 12 * 3600
# A secret shorter than this is refused: HMAC is only as strong as the key an attacker must guess.
MIN_SECRET_CHARS = 16
# Tokens travel in URL fragments and JSON frames; anything longer than this is not one of ours.
MAX_TOKEN_CHARS = 1024

Reason = Literal["malformed", "bad signature", "expired", "wrong room", "wrong role"]


class TokenError(ValueError):
    """A token was refused; ``reason`` says why in words a log or a page can show."""

    def __init__(self, reason: Reason, detail: str = "") -> None:
        super().__init__(f"token refused: {reason}" + (f" ({detail})" if detail else ""))
        self.reason: Reason = reason


@dataclass(frozen=True)
class Claims:
    """What a valid token grants: ``role`` in ``room`` until ``exp`` (Unix seconds)."""

    room: str
    role: Role
    exp: int


def check_secret(secret: str) -> None:
    """Raise ``ValueError`` unless ``secret`` is long enough to sign with."""
    if len(secret) < MIN_SECRET_CHARS:
        raise ValueError(
            f"the secret must be at least {MIN_SECRET_CHARS} characters "
            f"(got {len(secret)}); generate one with: python3 -c "
            "'import secrets; print(secrets.token_urlsafe(32))'"
        )


def sign(secret: str, room: str, role: Role, *, now: float, ttl_s: float = DEFAULT_TTL_S) -> str:
    """A token granting ``role`` in ``room`` for ``ttl_s`` seconds from ``now``."""
    check_secret(secret)
    if role not in ROLES:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, not {role!r}")
    # NaN and infinity would fail in int() below, or mint a token that never expires.
    if not math.isfinite(ttl_s) or ttl_s <= 0:
        raise ValueError(f"ttl must be a positive finite number of seconds, not {ttl_s}")
    payload = json.dumps(
        {"room": room, "role": role, "exp": int(now + ttl_s)}, separators=(",", ":")
    ).encode()
    body = _b64encode(payload)
    return f"{body}.{_b64encode(_mac(secret, body))}"


def verify(
    secret: str,
    token: str,
    *,
    now: float,
    room: str | None = None,
    roles: Collection[Role] | None = None,
) -> Claims:
    """The claims of ``token`` if it is genuine, unexpired and fits; else :class:`TokenError`.

    ``room=None`` accepts any room and ``roles=None`` any role (reading the simulator's state).
    """
    if not isinstance(token, str) or len(token) > MAX_TOKEN_CHARS or token.count(".") != 1:
        raise TokenError("malformed", "expected <payload>.<signature>")
    body, signature = token.split(".")
    try:
        given = _b64decode(signature)
    except ValueError as exc:
        raise TokenError("malformed", "signature is not base64url") from exc
    # Checked before the payload is even parsed: nothing unsigned reaches json.loads.
    if not hmac.compare_digest(given, _mac(secret, body)):
        raise TokenError("bad signature", "not signed with this server's secret")
    claims = _claims(body)
    if claims.exp <= now:
        raise TokenError("expired", f"{int(now - claims.exp)} s ago")
    if room is not None and claims.room != room:
        raise TokenError("wrong room", f"token is for room {claims.room!r}, not {room!r}")
    if roles is not None and claims.role not in roles:
        raise TokenError(
            "wrong role", f"token is for {claims.role!r}, this needs {' or '.join(roles)}"
        )
    return claims


def _claims(body: str) -> Claims:
    try:
        data = json.loads(_b64decode(body))
    except (ValueError, UnicodeDecodeError) as exc:
        raise TokenError("malformed", "payload is not JSON") from exc
    if not isinstance(data, dict):
        raise TokenError("malformed", "payload is not an object")
    room, role, exp = data.get("room"), data.get("role"), data.get("exp")
    if not isinstance(room, str) or role not in ROLES or type(exp) is not int:
        raise TokenError("malformed", "payload needs room, role and exp")
    return Claims(room=room, role=role, exp=exp)


def _mac(secret: str, body: str) -> bytes:
    return hmac.new(secret.encode(), body.encode(), hashlib.sha256).digest()


def _b64encode(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode("ascii")


def _b64decode(text: str) -> bytes:
    try:
        return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))
    except (binascii.Error, ValueError) as exc:
        raise ValueError(f"not base64url: {exc}") from exc
