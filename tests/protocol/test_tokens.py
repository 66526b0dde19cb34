"""Room- and role-scoped tokens: what they grant, and each reason one is refused."""

from __future__ import annotations

import base64
import json
import math

import pytest

from app.protocol import tokens
from app.protocol.tokens import TokenError

SECRET = "a-secret-of-sufficient-length"
NOW = 1_800_000_000.0


def test_a_token_grants_its_role_in_its_room_until_it_expires() -> None:
    token = tokens.sign(SECRET, "lab", "relay", now=NOW, ttl_s=60)
    claims = tokens.verify(SECRET, token, now=NOW + 59, room="lab", roles=("relay",))
    assert (claims.room, claims.role, claims.exp) == ("lab", "relay", int(NOW + 60))


def test_any_room_and_role_when_the_caller_does_not_restrict() -> None:
    token = tokens.sign(SECRET, "lab", "client", now=NOW)
    assert tokens.verify(SECRET, token, now=NOW).role == "client"


@pytest.mark.parametrize(
    ("check", "reason"),
    [
        ({"now": NOW + 61}, "expired"),
        ({"now": NOW + 60}, "expired"),
        ({"now": NOW, "room": "other"}, "wrong room"),
        ({"now": NOW, "roles": ("vehicle",)}, "wrong role"),
        ({"now": NOW, "roles": ("vehicle", "client")}, "wrong role"),
    ],
)
def test_refusals_name_their_reason(check: dict[str, object], reason: str) -> None:
    token = tokens.sign(SECRET, "lab", "relay", now=NOW, ttl_s=60)
    with pytest.raises(TokenError) as refused:
        tokens.verify(SECRET, token, **check)  # type: ignore[arg-type]
    assert refused.value.reason == reason
    assert reason in str(refused.value)


def test_another_secret_or_an_altered_payload_is_a_bad_signature() -> None:
    token = tokens.sign(SECRET, "lab", "client", now=NOW)
    with pytest.raises(TokenError) as refused:
        tokens.verify("another-secret-of-some-length", token, now=NOW)
    assert refused.value.reason == "bad signature"
    # Promote oneself to relay by rewriting the payload and keeping the signature.
    body, signature = token.split(".")
    claims = json.loads(base64.urlsafe_b64decode(body + "=" * (-len(body) % 4)))
    claims["role"] = "relay"
    forged = base64.urlsafe_b64encode(json.dumps(claims).encode()).rstrip(b"=").decode()
    with pytest.raises(TokenError) as refused:
        tokens.verify(SECRET, f"{forged}.{signature}", now=NOW)
    assert refused.value.reason == "bad signature"


@pytest.mark.parametrize(
    "token", ["", "nodot", "a.b.c", "x" * 5000, "e30.!!!", "e30." + "A" * 43, "\u00e9.\u00e9"]
)
def test_garbage_is_refused_without_crashing(token: str) -> None:
    with pytest.raises(TokenError) as refused:
        tokens.verify(SECRET, token, now=NOW)
    assert refused.value.reason in ("malformed", "bad signature")


def test_a_signed_payload_that_is_not_ours_is_malformed() -> None:
    # Correctly signed, but missing the fields a token must have.
    body = base64.urlsafe_b64encode(b'{"room":"lab"}').rstrip(b"=").decode()
    signature = base64.urlsafe_b64encode(tokens._mac(SECRET, body)).rstrip(b"=").decode()
    with pytest.raises(TokenError) as refused:
        tokens.verify(SECRET, f"{body}.{signature}", now=NOW)
    assert refused.value.reason == "malformed"


def test_signing_needs_a_real_secret_a_known_role_and_a_positive_finite_ttl() -> None:
    with pytest.raises(ValueError, match="at least"):
        tokens.sign("short", "lab", "client", now=NOW)
    with pytest.raises(ValueError, match="role"):
        tokens.sign(SECRET, "lab", "admin", now=NOW)  # type: ignore[arg-type]
    for ttl_s in (0, -1, math.nan, math.inf):
        with pytest.raises(ValueError, match="ttl"):
            tokens.sign(SECRET, "lab", "client", now=NOW, ttl_s=ttl_s)


def test_a_renewal_continues_the_grant_with_the_same_lifetime() -> None:
    first = tokens.sign(SECRET, "lab", "relay", now=NOW, ttl_s=600)
    claims = tokens.verify(SECRET, first, now=NOW + 500)
    renewed = tokens.renewal(SECRET, claims, now=NOW + 500)
    again = tokens.verify(SECRET, renewed, now=NOW + 1000, room="lab", roles=("relay",))
    assert (again.exp, again.iat, again.grant) == (int(NOW + 1100), int(NOW + 500), claims.grant)
    assert claims.renew_in(NOW + 500) == 50  # half the time it has left


def _legacy(payload: dict[str, object]) -> str:
    """A token as minted before ``iat`` and ``gid`` (signed the same way)."""
    body = base64.urlsafe_b64encode(json.dumps(payload).encode()).rstrip(b"=").decode()
    return f"{body}.{tokens._b64encode(tokens._mac(SECRET, body))}"


def test_a_token_minted_before_renewals_is_accepted_but_not_renewed_by_the_server() -> None:
    legacy = _legacy({"room": "lab", "role": "client", "exp": int(NOW + 60)})
    claims = tokens.verify(SECRET, legacy, now=NOW)
    assert claims.iat is None and claims.grant == legacy.split(".")[1]
    with pytest.raises(ValueError, match="predates renewals"):
        tokens.renewal(SECRET, claims, now=NOW)


_ALPHABET = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_"


def _re_encodings(signature: str) -> list[str]:
    """Other spellings of the same signature bytes: padded, standard base64's alphabet, and the
    last character's unused low bits set (a 32-byte MAC leaves 2 of its 258 bits unused)."""
    raw = base64.urlsafe_b64decode(signature + "=")
    last = _ALPHABET.index(signature[-1])
    return [
        signature + "=",
        base64.b64encode(raw).decode(),  # '+' and '/' for '-' and '_', and padded
        base64.b64encode(raw).decode().rstrip("="),
        signature[:-1] + _ALPHABET[last | 1],
        signature[:-1] + _ALPHABET[last | 2],
    ]


def test_a_signature_is_accepted_in_its_one_canonical_encoding_only() -> None:
    # Issue 37.13: padded and standard-base64 spellings of a valid signature were accepted.
    now = NOW
    token = tokens.sign(SECRET, "lab", "client", now=now)
    # One whose signature has a character standard base64 spells differently.
    while not {"-", "_"} & set(token.split(".")[1]):
        now += 1
        token = tokens.sign(SECRET, "lab", "client", now=now)
    body, signature = token.split(".")
    assert tokens.verify(SECRET, token, now=now).role == "client"
    raw = base64.urlsafe_b64decode(signature + "=")
    others = [other for other in _re_encodings(signature) if other != signature]
    assert len(set(others)) == 5
    for other in others:
        unpadded = other.rstrip("=")
        # The same bytes, as a lenient decoder reads them ...
        assert base64.urlsafe_b64decode(unpadded + "=" * (-len(unpadded) % 4)) == raw
        # ... but not the token's spelling.
        with pytest.raises(TokenError) as refused:
            tokens.verify(SECRET, f"{body}.{other}", now=now)
        assert refused.value.reason in ("malformed", "bad signature"), other


@pytest.mark.parametrize(
    ("target", "headers", "expected"),
    [
        ("/?token=abc.def", {}, "abc.def"),
        ("/?room=x&token=abc.def", {}, "abc.def"),
        ("/", {"authorization": "Bearer abc.def"}, "abc.def"),
        # The header wins over the query.
        ("/?token=q.q", {"authorization": "Bearer h.h"}, "h.h"),
        ("/", {"authorization": "Basic abc"}, None),
        ("/?token=", {}, None),
        ("/", {}, None),
    ],
)
def test_a_handshake_offers_its_token_in_a_bearer_header_or_the_query(
    target: str, headers: dict[str, str], expected: str | None
) -> None:
    assert tokens.request_token(target, headers) == expected
