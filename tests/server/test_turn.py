"""TURN REST credentials and the TURN settings, without a network (coturn's side:
``tests/tools/lab/test_turn.py``)."""

from __future__ import annotations

import base64
import subprocess

import pytest
from pydantic import ValidationError

from app.server.turn import TurnSettings, mint_turn_credentials


def test_username_is_expiry_colon_name() -> None:
    username, _ = mint_turn_credentials("s3cret", "robot-1", 600, now=1_700_000_000.7)
    assert username == "1700000600:robot-1"


def test_password_is_what_openssl_computes_for_the_username() -> None:
    username, password = mint_turn_credentials("s3cret", "op", 60, now=1_000)
    digest = subprocess.run(
        ["openssl", "dgst", "-sha1", "-hmac", "s3cret", "-binary"],
        input=username.encode(),
        capture_output=True,
        check=True,
    ).stdout
    assert password == base64.b64encode(digest).decode()


def test_names_and_secrets_give_different_passwords() -> None:
    a = mint_turn_credentials("one", "robot", 60, now=0)
    b = mint_turn_credentials("two", "robot", 60, now=0)
    c = mint_turn_credentials("one", "client", 60, now=0)
    assert len({a[1], b[1], c[1]}) == 3


@pytest.mark.parametrize(("name", "ttl"), [("a:b", 60), ("robot", 0), ("robot", -5)])
def test_bad_name_or_ttl_is_refused(name: str, ttl: int) -> None:
    with pytest.raises(ValueError):
        mint_turn_credentials("s", name, ttl, now=0)


def test_settings_default_to_no_turn_and_policy_all() -> None:
    settings = TurnSettings()
    assert settings.turn_urls == [] and settings.ice_transport_policy == "all"


@pytest.mark.parametrize(
    ("fields", "complaint"),
    [
        ({"turn_urls": ["turn:10.0.0.1:3478"]}, "secret"),
        ({"turn_urls": ["http://x"], "secret": "s"}, "turn:"),
        ({"stun_urls": ["turn:x"]}, "stun:"),
        ({"ice_transport_policy": "relay"}, "TURN url"),
        ({"credential_ttl_s": 0}, "greater than 0"),
    ],
)
def test_inconsistent_settings_are_refused_with_the_reason(
    fields: dict[str, object], complaint: str
) -> None:
    with pytest.raises(ValidationError, match=complaint):
        TurnSettings.model_validate(fields)
