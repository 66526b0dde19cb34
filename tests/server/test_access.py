"""``/rosbridge`` access: the first message proves a token; only a vehicle token drives."""

from __future__ import annotations

import json

import pytest

from app.protocol import tokens
from app.protocol.close_codes import CloseCode
from app.server.access import (
    Decision,
    RosbridgeGate,
    bearer_token,
    state_refusal,
)

SECRET = "rosbridge-gate-test-secret"
NOW = 1_800_000_000.0
PUBLISH = json.dumps({"op": "publish", "topic": "/turtle1/cmd_vel", "msg": {}})
SUBSCRIBE = json.dumps({"op": "subscribe", "topic": "/turtle1/pose"})
KILL = json.dumps({"op": "call_service", "service": "/kill", "args": {"name": "turtle1"}, "id": 7})
TOPICS = json.dumps({"op": "call_service", "service": "/rosapi/topics"})


def _token(role: tokens.Role, room: str = "lab", ttl_s: float = 60) -> str:
    return tokens.sign(SECRET, room, role, now=NOW, ttl_s=ttl_s)


def _auth(token: str) -> str:
    return json.dumps({"op": "auth", "token": token})


def test_without_a_secret_everything_passes_and_auth_is_swallowed() -> None:
    gate = RosbridgeGate(secret=None)
    assert gate.check(PUBLISH, NOW).forward
    assert not gate.check(_auth("whatever"), NOW).forward


@pytest.mark.parametrize("first", [PUBLISH, "not json", "[1, 2]", "9" * 5000, "[" * 3000])
def test_anything_but_a_token_first_is_refused_and_closed(first: str) -> None:
    decision = RosbridgeGate(SECRET).check(first, NOW)
    assert not decision.forward
    assert decision.close is not None and decision.close[0] == CloseCode.POLICY_VIOLATION
    assert decision.reply is not None and "authenticate first" in decision.reply["msg"]


def test_a_vehicle_token_drives() -> None:
    gate = RosbridgeGate(SECRET)
    assert gate.check(_auth(_token("vehicle")), NOW) == Decision(forward=False)
    for frame in (PUBLISH, KILL, SUBSCRIBE):
        assert gate.check(frame, NOW).forward


@pytest.mark.parametrize("role", ["relay", "client"])
def test_other_roles_only_read(role: tokens.Role) -> None:
    gate = RosbridgeGate(SECRET)
    assert not gate.check(_auth(_token(role)), NOW).forward
    assert gate.check(SUBSCRIBE, NOW).forward
    assert gate.check(TOPICS, NOW).forward
    for frame in (PUBLISH, KILL):
        decision = gate.check(frame, NOW)
        assert not decision.forward and decision.close is None
        assert decision.reply is not None and "needs a vehicle token" in decision.reply["msg"]
    assert gate.check(KILL, NOW).reply == {
        "op": "status",
        "level": "error",
        "msg": f"'call_service' changes the simulator and needs a vehicle token; "
        f"this connection has a {role} token",
        "id": 7,
    }


def test_a_token_in_the_first_message_itself_and_roslibjs_mac() -> None:
    gate = RosbridgeGate(SECRET)
    first = json.dumps({"op": "subscribe", "topic": "/turtle1/pose", "token": _token("client")})
    assert gate.check(first, NOW).forward
    other = RosbridgeGate(SECRET)
    assert not other.check(json.dumps({"op": "auth", "mac": _token("vehicle")}), NOW).forward
    assert other.check(PUBLISH, NOW).forward


@pytest.mark.parametrize(
    ("token", "words"),
    [
        (tokens.sign(SECRET, "lab", "vehicle", now=NOW - 120, ttl_s=60), "expired"),
        (tokens.sign("some-other-secret-value", "lab", "vehicle", now=NOW), "bad signature"),
        ("garbage", "malformed"),
    ],
)
def test_bad_tokens_are_refused_with_their_reason(token: str, words: str) -> None:
    decision = RosbridgeGate(SECRET).check(_auth(token), NOW)
    assert decision.close is not None and not decision.forward
    assert decision.reply is not None and words in decision.reply["msg"]


def test_the_handshake_header_authenticates_too() -> None:
    gate = RosbridgeGate(SECRET)
    assert gate.handshake(_token("vehicle"), NOW) is None
    assert gate.check(PUBLISH, NOW).forward
    refused = RosbridgeGate(SECRET).handshake("garbage", NOW)
    assert refused is not None and "malformed" in refused


def test_bearer_header_and_state_reads() -> None:
    assert bearer_token({"authorization": "Bearer abc.def"}) == "abc.def"
    assert bearer_token({"authorization": "Basic abc"}) is None
    assert bearer_token({}) is None
    assert state_refusal(None, None, NOW) is None
    assert state_refusal(SECRET, _token("client", room="any"), NOW) is None
    assert "Bearer" in (state_refusal(SECRET, None, NOW) or "")
    assert "bad signature" in (state_refusal(SECRET, "e30.AAAA", NOW) or "")
