"""Short-lived credentials scoped to one room and one role, signed with ``AUTOPILOT_SECRET``.

A token is ``<payload>.<signature>``, both base64url without padding: the payload is the compact
JSON ``{"room": R, "role": ROLE, "exp": UNIX_SECONDS, "iat": UNIX_SECONDS, "gid": GRANT}`` and the
signature is HMAC-SHA256 of the encoded payload under the server's secret, accepted in that one
spelling only. ``iat`` (when it was
issued) gives the token's lifetime, which :func:`renewal` keeps; ``gid`` names the grant a
renewed token continues (absent from a grant's first token, whose signature names it), so that
what is counted per token -- its sessions in a room -- is counted per grant, renewals included.
Tokens without ``iat`` or ``gid`` (minted before them) are still accepted. Nothing here reads a
clock or the environment: callers pass ``now`` and the secret, so the rules are tested directly.

A room's roles (vehicle, relay, client) are the peers' own. One more, ``fleet``, is the scope of
the fleet view (``/fleet/rooms``) of every room: its room is :data:`ALL_ROOMS`, and it admits to
nothing else -- :func:`verify` accepts only the room roles unless told otherwise.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import json
import math
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Final, Literal, get_args
from urllib.parse import parse_qs, urlsplit

from app.protocol.rooms import Role as Role  # re-exported: tokens.Role

ROLES: tuple[Role, ...] = get_args(Role)
# What a token may grant: a role in a room, or the fleet view of every room.
TokenRole = Role | Literal["fleet"]
TOKEN_ROLES: tuple[TokenRole, ...] = (*ROLES, "fleet")
# The room a fleet token names: every room (no room may be named so in a login that matters,
# since a fleet token logs in nowhere).
ALL_ROOMS: Final = "*"

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
# An HMAC-SHA256 (32 bytes) in base64url without padding: 43 characters, the last of which has
# two unused low bits, always zero as the encoder writes them.
_CANONICAL_SIGNATURE = re.compile(r"[A-Za-z0-9_-]{42}[AEIMQUYcgkosw048]")

Reason = Literal["malformed", "bad signature", "expired", "wrong room", "wrong role"]


class TokenError(ValueError):
    """A token was refused; ``reason`` says why in words a log or a page can show."""

    def __init__(self, reason: Reason, detail: str = "") -> None:
        super().__init__(f"token refused: {reason}" + (f" ({detail})" if detail else ""))
        self.reason: Reason = reason


# A session renews its token once this fraction of the time it has left has passed: half, as a
# DHCP client renews its lease, leaves the other half for a late timer and the round trip.
RENEW_AFTER: Final = 0.5


@dataclass(frozen=True)
class Claims:
    """What a valid token grants: ``role`` in ``room`` until ``exp`` (Unix seconds), as part
    of ``grant``; ``iat`` is when it was issued (None: a token minted before renewals)."""

    room: str
    role: TokenRole
    exp: int
    grant: str
    iat: int | None = None

    def renew_in(self, now: float) -> float:
        """Seconds from ``now`` until a session holding this token should renew it."""
        return max(0.0, RENEW_AFTER * (self.exp - now))


def check_secret(secret: str) -> None:
    """Raise ``ValueError`` unless ``secret`` is long enough to sign with."""
    if len(secret) < MIN_SECRET_CHARS:
        raise ValueError(
            f"the secret must be at least {MIN_SECRET_CHARS} characters "
            f"(got {len(secret)}); generate one with: python3 -c "
            "'import secrets; print(secrets.token_urlsafe(32))'"
        )


def sign(
    secret: str,
    room: str,
    role: TokenRole,
    *,
    now: float,
    ttl_s: float = DEFAULT_TTL_S,
    grant: str | None = None,
) -> str:
    """A token granting ``role`` in ``room`` (a fleet token: :data:`ALL_ROOMS`) for ``ttl_s``
    seconds from ``now``; ``grant`` when it renews one (:func:`renewal`)."""
    check_secret(secret)
    if role not in TOKEN_ROLES:
        raise ValueError(f"role must be one of {', '.join(TOKEN_ROLES)}, not {role!r}")
    if (role == "fleet") != (room == ALL_ROOMS):
        raise ValueError(f"a fleet token, and only a fleet token, is for room {ALL_ROOMS!r}")
    # NaN and infinity would fail in int() below, or mint a token that never expires.
    if not math.isfinite(ttl_s) or ttl_s <= 0:
        raise ValueError(f"ttl must be a positive finite number of seconds, not {ttl_s}")
    fields: dict[str, object] = {
        "room": room,
        "role": role,
        "exp": int(now + ttl_s),
        "iat": int(now),
    }
    if grant is not None:
        fields["gid"] = grant
    body = _b64encode(json.dumps(fields, separators=(",", ":")).encode())
    return f"{body}.{_b64encode(_mac(secret, body))}"


def renewal(secret: str, claims: Claims, *, now: float) -> str:
    """A fresh token continuing ``claims``' grant: same room and role, the same lifetime from
    ``now``. ``ValueError`` for a token that does not say when it was issued."""
    if claims.iat is None:
        raise ValueError("this token predates renewals (it has no issue time)")
    lifetime = max(1, claims.exp - claims.iat)
    return sign(secret, claims.room, claims.role, now=now, ttl_s=lifetime, grant=claims.grant)


def verify(
    secret: str,
    token: str,
    *,
    now: float,
    room: str | None = None,
    roles: Collection[TokenRole] = ROLES,
) -> Claims:
    """The claims of ``token`` if it is genuine, unexpired and fits; else :class:`TokenError`.

    ``room=None`` accepts any room; ``roles`` are the roles accepted, by default a room's
    (a fleet token is accepted only where ``roles`` names it).
    """
    if not isinstance(token, str) or len(token) > MAX_TOKEN_CHARS or token.count(".") != 1:
        raise TokenError("malformed", "expected <payload>.<signature>")
    body, signature = token.split(".")
    if not _CANONICAL_SIGNATURE.fullmatch(signature):
        raise TokenError("malformed", "signature is not 43 characters of unpadded base64url")
    # The signature's one spelling, compared as text: a padded, standard-alphabet or otherwise
    # re-encoded spelling of the same bytes is another token, and refused. Checked before the
    # payload is even parsed: nothing unsigned reaches json.loads.
    if not hmac.compare_digest(signature, _b64encode(_mac(secret, body))):
        raise TokenError("bad signature", "not signed with this server's secret")
    claims = _claims(body, signature)
    if claims.exp <= now:
        raise TokenError("expired", f"{int(now - claims.exp)} s ago")
    if room is not None and claims.room != room:
        raise TokenError("wrong room", f"token is for room {claims.room!r}, not {room!r}")
    if claims.role not in roles:
        raise TokenError(
            "wrong role", f"token is for {claims.role!r}, this needs {' or '.join(roles)}"
        )
    return claims


def bearer_token(headers: Mapping[str, str]) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header, or None."""
    value = headers.get("authorization", "")
    scheme, _, token = value.partition(" ")
    return token.strip() or None if scheme.lower() == "bearer" else None


def request_token(target: str, headers: Mapping[str, str]) -> str | None:
    """The token a WebSocket handshake offers: its ``Authorization: Bearer`` header's, else the
    ``token`` of its request target's query (``/?token=T``: a browser's WebSocket cannot send a
    header); None without either."""
    found = bearer_token(headers)
    if found is not None:
        return found
    values = parse_qs(urlsplit(target).query).get("token")
    return values[0] if values else None


def _claims(body: str, signature: str) -> Claims:
    try:
        data = json.loads(_b64decode(body))
    except (ValueError, UnicodeDecodeError) as exc:
        raise TokenError("malformed", "payload is not JSON") from exc
    if not isinstance(data, dict):
        raise TokenError("malformed", "payload is not an object")
    room, role, exp = data.get("room"), data.get("role"), data.get("exp")
    if not isinstance(room, str) or role not in TOKEN_ROLES or type(exp) is not int:
        raise TokenError("malformed", "payload needs room, role and exp")
    iat, grant = data.get("iat"), data.get("gid", signature)
    if (iat is not None and type(iat) is not int) or not isinstance(grant, str):
        raise TokenError("malformed", "iat must be an integer and gid a string")
    return Claims(room=room, role=role, exp=exp, grant=grant, iat=iat)


def _mac(secret: str, body: str) -> bytes:
    return hmac.new(secret.encode(), body.encode(), hashlib.sha256).digest()


def _b64encode(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode("ascii")


def _b64decode(text: str) -> bytes:
    try:
        return base64.urlsafe_b64decode(text + "=" * (-len(text) % 4))
    except (binascii.Error, ValueError) as exc:
        raise ValueError(f"not base64url: {exc}") from exc
