"""TURN REST credentials and the TURN settings, without a network (coturn's side:
``tests/tools/lab/test_turn.py``)."""

from __future__ import annotations

import base64
import json
import subprocess
import time
from typing import Any

import pytest
from pydantic import SecretStr, ValidationError

from app.protocol.signaling import IceServer
from app.server.config import Settings
from app.server.signaling import Switchboard
from app.server.turn import TurnSettings, mint_turn_credentials
from app.signaling.hub import Outgoing


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
        ({"turn_urls": ["http://x"], "turn_secret": "s"}, "turn:"),
        ({"stun_urls": ["turn:x"]}, "stun:"),
        ({"ice_transport_policy": "relay"}, "TURN url"),
        ({"turn_credential_ttl_s": 0}, "greater than 0"),
    ],
)
def test_inconsistent_settings_are_refused_with_the_reason(
    fields: dict[str, object], complaint: str
) -> None:
    with pytest.raises(ValidationError, match=complaint):
        TurnSettings.model_validate(fields)


def _login_reply(settings: Settings, name: str) -> dict[str, Any]:
    hub = Switchboard.from_settings(settings).hub
    conn = hub.connect()
    login = json.dumps({"type": "login", "name": name, "role": "vehicle"})
    reply = next(a for a in hub.receive(conn, login) if isinstance(a, Outgoing))
    return reply.message


def test_login_reply_carries_stun_minted_turn_extras_and_the_policy() -> None:
    settings = Settings(
        environment="development",
        stun_urls=["stun:10.0.0.1:3478"],
        turn_urls=["turn:10.0.0.1:3478?transport=udp"],
        turn_secret=SecretStr("coturn-secret"),
        turn_credential_ttl_s=600,
        ice_transport_policy="relay",
        ice_servers=[IceServer(urls=["stun:extra.example:3478"])],
    )
    before = time.time()
    reply = _login_reply(settings, "robot:7")
    assert reply["iceTransportPolicy"] == "relay"
    stun, turn, extra = reply["iceServers"]
    assert stun == {"urls": ["stun:10.0.0.1:3478"]}
    assert extra == {"urls": ["stun:extra.example:3478"]}
    assert turn["urls"] == ["turn:10.0.0.1:3478?transport=udp"]
    expiry, name = turn["username"].split(":")
    assert name == "robot_7"  # the name's own ':' would end the expiry early
    assert before + 600 <= int(expiry) + 1 and int(expiry) <= time.time() + 600
    assert (
        turn["credential"]
        == mint_turn_credentials("coturn-secret", name, 600, int(expiry) - 600)[1]
    )
    assert "coturn-secret" not in json.dumps(reply)


def test_without_turn_a_login_gets_the_configured_servers_and_policy_all() -> None:
    reply = _login_reply(Settings(environment="development"), "client")
    assert reply["iceServers"] == [] and reply["iceTransportPolicy"] == "all"


def test_policy_comes_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("AUTOPILOT_ICE_TRANSPORT_POLICY", "relay")
    monkeypatch.setenv("AUTOPILOT_TURN_URLS", '["turn:10.0.0.1:3478"]')
    monkeypatch.setenv("AUTOPILOT_TURN_SECRET", "s")
    settings = Settings()
    assert settings.ice_transport_policy == "relay" and settings.turn_urls == ["turn:10.0.0.1:3478"]
