"""``/rosbridge`` access: the first message proves a token; only a vehicle token drives."""

from __future__ import annotations

import json

import pytest

from app.protocol import tokens
from app.protocol.close_codes import CloseCode
from app.protocol.tokens import bearer_token
from app.rosbridge.protocol import Operation, Refused, parse_frame
from app.rosbridge.rosapi import ROSAPI_READS
from app.server.access import (
    ROSBRIDGE_RIGHTS,
    Decision,
    RosbridgeGate,
    bearer_claims,
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


def _check(gate: RosbridgeGate, text: str, now: float = NOW) -> Decision:
    """The gate's decision on one text frame, parsed as the adapter parses it."""
    return gate.check(parse_frame(text), now)


def test_without_a_secret_everything_passes_and_auth_is_swallowed() -> None:
    gate = RosbridgeGate(secret=None)
    assert _check(gate, PUBLISH).forward
    assert not _check(gate, _auth("whatever")).forward


@pytest.mark.parametrize("first", [PUBLISH, "not json", "[1, 2]", "9" * 5000, "[" * 3000])
def test_anything_but_a_token_first_is_refused_and_closed(first: str) -> None:
    decision = _check(RosbridgeGate(SECRET), first)
    assert not decision.forward
    assert decision.close is not None and decision.close[0] == CloseCode.POLICY_VIOLATION
    assert decision.reply is not None and "authenticate first" in decision.reply["msg"]


def test_a_vehicle_token_drives() -> None:
    gate = RosbridgeGate(SECRET)
    assert _check(gate, _auth(_token("vehicle"))) == Decision(forward=False)
    for frame in (PUBLISH, KILL, SUBSCRIBE):
        assert _check(gate, frame).forward


@pytest.mark.parametrize("role", ["relay", "client"])
def test_other_roles_only_read(role: tokens.Role) -> None:
    gate = RosbridgeGate(SECRET)
    assert not _check(gate, _auth(_token(role))).forward
    assert _check(gate, SUBSCRIBE).forward
    assert _check(gate, TOPICS).forward
    for frame in (PUBLISH, KILL):
        decision = _check(gate, frame, NOW)
        assert not decision.forward and decision.close is None
        assert decision.reply is not None and "needs a vehicle token" in decision.reply["msg"]
    assert _check(gate, KILL).reply == {
        "op": "status",
        "level": "error",
        "msg": f"call_service '/kill' needs a vehicle token: a {role} token may only read",
        "id": 7,
    }


def _op(op: str, **fields: object) -> Operation:
    frame = parse_frame(json.dumps({"op": op, **fields}))
    assert not isinstance(frame, Refused), frame
    return frame


def _service(name: str) -> Operation:
    return _op("call_service", service=name)


# What a reader may do: watch the turtles and ask rosapi about the graph, parameters and clock.
READS = [
    _op("subscribe", topic="/turtle1/pose"),
    _op("subscribe", topic="/turtle1/cmd_vel"),
    _op("unsubscribe", topic="/turtle1/pose"),
    _op("set_level", level="error"),
    *[_service(f"{slash}rosapi/{name}") for slash in ("/", "") for name in ROSAPI_READS],
]
# ... and nothing that publishes, changes the simulator or sets a parameter (issue 37.3).
WRITES = [
    _op("publish", topic="/turtle1/cmd_vel", msg={}),
    _op("advertise", topic="/turtle1/cmd_vel"),
    _op("unadvertise", topic="/turtle1/cmd_vel"),
    *[
        _service(name)
        for name in (
            "/spawn",
            "kill",
            "/reset",
            "/clear",
            "/turtle1/teleport_absolute",
            "/turtle1/teleport_relative",
            "/turtle1/set_pen",
            "/rosapi/set_param",
            "rosapi/set_param",
            "/rosapi/delete_param",
            "/rosapi/../spawn",
            "//rosapi/topics",
        )
    ],
]


@pytest.mark.parametrize("role", ["relay", "client"])
def test_readers_rights_are_the_reads_and_nothing_else(role: tokens.Role) -> None:
    rights = ROSBRIDGE_RIGHTS[role]
    assert [op for op in READS if not rights.allows(op)] == []
    assert [op for op in WRITES if rights.allows(op)] == []


def test_a_vehicle_may_do_everything() -> None:
    assert all(ROSBRIDGE_RIGHTS["vehicle"].allows(op) for op in READS + WRITES)


def test_every_role_has_its_rights_written_down() -> None:
    assert set(ROSBRIDGE_RIGHTS) == set(tokens.TOKEN_ROLES)
    assert ROSBRIDGE_RIGHTS["fleet"].ops == frozenset()


def test_a_token_in_the_first_message_itself_and_roslibjs_mac() -> None:
    gate = RosbridgeGate(SECRET)
    first = json.dumps({"op": "subscribe", "topic": "/turtle1/pose", "token": _token("client")})
    assert _check(gate, first).forward
    other = RosbridgeGate(SECRET)
    assert not _check(other, json.dumps({"op": "auth", "mac": _token("vehicle")})).forward
    assert _check(other, PUBLISH).forward


@pytest.mark.parametrize(
    ("token", "words"),
    [
        (tokens.sign(SECRET, "lab", "vehicle", now=NOW - 120, ttl_s=60), "expired"),
        (tokens.sign("some-other-secret-value", "lab", "vehicle", now=NOW), "bad signature"),
        ("garbage", "malformed"),
    ],
)
def test_bad_tokens_are_refused_with_their_reason(token: str, words: str) -> None:
    decision = _check(RosbridgeGate(SECRET), _auth(token), NOW)
    assert decision.close is not None and not decision.forward
    assert decision.reply is not None and words in decision.reply["msg"]


def test_the_handshake_header_authenticates_too() -> None:
    gate = RosbridgeGate(SECRET)
    assert gate.handshake(_token("vehicle"), NOW) is None
    assert _check(gate, PUBLISH).forward
    refused = RosbridgeGate(SECRET).handshake("garbage", NOW)
    assert refused is not None and "malformed" in refused


def test_bearer_header_and_state_reads() -> None:
    assert bearer_token({"authorization": "Bearer abc.def"}) == "abc.def"
    assert bearer_token({"authorization": "Basic abc"}) is None
    assert bearer_token({}) is None
    claims = bearer_claims(SECRET, _token("client", room="any"), NOW)
    assert not isinstance(claims, str) and claims.room == "any"
    assert "Bearer" in str(bearer_claims(SECRET, None, NOW))
    assert "bad signature" in str(bearer_claims(SECRET, "e30." + "A" * 43, NOW))
    assert "malformed" in str(bearer_claims(SECRET, "e30.AAAA", NOW))


@pytest.mark.parametrize("op", [["publish"], {"op": "publish"}, 7, None, True])
@pytest.mark.parametrize("role", ["vehicle", "relay", "client"])
def test_a_frame_whose_op_is_not_a_string_goes_to_the_session_to_be_explained(
    op: object, role: tokens.Role
) -> None:
    # Issue 37.2: with a reader's token the gate raised TypeError on an op that is a list.
    gate = RosbridgeGate(SECRET)
    _check(gate, _auth(_token(role)))
    assert _check(gate, json.dumps({"op": op, "id": 3})) == Decision(forward=True)
