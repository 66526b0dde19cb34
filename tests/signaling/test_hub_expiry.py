"""Sessions end with their tokens unless renewed (issue 37.4), on the sans-I/O hub with an
injected clock."""

from __future__ import annotations

import json
from typing import Any

from app.protocol import tokens
from app.protocol.rooms import Role
from app.signaling.hub import MAX_TOKEN_SESSIONS, Action, Close, Hub, Outgoing
from tests.helpers.clock import Clock

SECRET = "hub-expiry-test-secret"
LIFETIME_S = 60
NOW = 1_800_000_000.0


def to(conn: str, actions: list[Action]) -> list[dict[str, Any]]:
    return [a.message for a in actions if isinstance(a, Outgoing) and a.conn == conn]


def closes(actions: list[Action]) -> list[Close]:
    return [a for a in actions if isinstance(a, Close)]


def login(hub: Hub, name: str, role: Role, token: str) -> tuple[str, dict[str, Any]]:
    conn = hub.connect()
    message = {"type": "login", "name": name, "role": role, "room": "lab", "token": token}
    return conn, to(conn, hub.receive(conn, json.dumps(message)))[0]


def token(clock: Clock, role: Role, ttl_s: float = LIFETIME_S, room: str = "lab") -> str:
    return tokens.sign(SECRET, room, role, now=clock.now, ttl_s=ttl_s)


def test_a_session_ends_when_its_token_expires() -> None:
    clock = Clock(NOW)
    hub = Hub(secret=SECRET, clock=clock)
    relay, reply = login(hub, "r", "relay", token(clock, "relay"))
    assert reply["renewIn"] == LIFETIME_S / 2  # renew with half the time to spare
    vehicle, _ = login(hub, "v", "vehicle", token(clock, "vehicle", 3600))
    clock.now += LIFETIME_S - 0.1
    assert hub.expire() == []
    clock.now += 0.1
    actions = hub.expire()
    (error,) = to(relay, actions)
    assert error["type"] == "error" and error["reason"].startswith("token expired")
    assert "autopilot token --room lab --role relay" in error["reason"]
    assert [(c.conn, c.code, c.reason) for c in closes(actions)] == [(relay, 1008, "token expired")]
    assert to(vehicle, actions) == [
        {"type": "leave", "from": "r"},
        {"type": "peers", "room": "lab", "peers": []},
    ]
    assert [p.model_dump() for p in hub.roster("lab")] == [{"name": "v", "role": "vehicle"}]
    assert hub.receive(relay, '{"type": "getOps"}') == []  # closing: nothing more is read


def test_a_frame_after_expiry_ends_the_session_and_goes_nowhere() -> None:
    clock = Clock(NOW)
    hub = Hub(secret=SECRET, clock=clock)
    relay, _ = login(hub, "r", "relay", token(clock, "relay", 3600))
    vehicle, _ = login(hub, "v", "vehicle", token(clock, "vehicle"))
    clock.now += LIFETIME_S  # expired, and no sweep has run yet
    actions = hub.receive(vehicle, json.dumps({"type": "offer", "to": "r", "sdp": "v=0"}))
    assert [m["type"] for m in to(relay, actions)] == ["leave", "peers"]  # no offer
    assert [c.reason for c in closes(actions)] == ["token expired"]


def test_renew_gives_a_fresh_token_of_the_same_grant_and_the_session_lives_on() -> None:
    clock = Clock(NOW)
    hub = Hub(secret=SECRET, clock=clock)
    first = token(clock, "client")
    grant = tokens.verify(SECRET, first, now=clock.now).grant
    client, _ = login(hub, "c", "client", first)
    for _ in range(5):  # five lifetimes, renewed when the login or the last renewal said
        clock.now += LIFETIME_S / 2
        assert hub.expire() == []
        (renewed,) = to(client, hub.receive(client, '{"type": "renew"}'))
        assert renewed["type"] == "renewed" and renewed["renewIn"] == LIFETIME_S / 2
        claims = tokens.verify(SECRET, renewed["token"], now=clock.now, room="lab")
        assert claims.role == "client" and claims.exp == int(clock.now + LIFETIME_S)
        assert claims.grant == grant
    assert hub.logged_in(client)
    clock.now += LIFETIME_S  # and without a renewal it ends
    assert [c.reason for c in closes(hub.expire())] == ["token expired"]


def test_a_token_brought_to_renew_must_be_for_the_room_and_role() -> None:
    clock = Clock(NOW)
    hub = Hub(secret=SECRET, clock=clock)
    relay, _ = login(hub, "r", "relay", token(clock, "relay"))
    for wrong in (token(clock, "relay", room="elsewhere"), token(clock, "client"), "garbage"):
        (error,) = to(relay, hub.receive(relay, json.dumps({"type": "renew", "token": wrong})))
        assert error["ref"] == "renew" and error["reason"].startswith("cannot renew")
    longer = token(clock, "relay", 3600)
    (renewed,) = to(relay, hub.receive(relay, json.dumps({"type": "renew", "token": longer})))
    assert renewed["token"] == longer
    clock.now += LIFETIME_S * 2
    assert hub.expire() == []  # the brought token's expiry counts now


def test_renewed_tokens_count_as_the_grant_they_continue() -> None:
    # Otherwise each renewal would be a new token, and one grant could take every place.
    clock = Clock(NOW)
    hub = Hub(secret=SECRET, clock=clock)
    client, _ = login(hub, "c0", "client", token(clock, "client"))
    (renewed,) = to(client, hub.receive(client, '{"type": "renew"}'))
    replies = [login(hub, f"c{n}", "client", renewed["token"])[1] for n in range(1, 6)]
    assert [r["success"] for r in replies] == [True] * (MAX_TOKEN_SESSIONS - 1) + [False] * (
        6 - MAX_TOKEN_SESSIONS
    )


def test_without_a_secret_there_is_nothing_to_renew_or_expire() -> None:
    clock = Clock(NOW)
    hub = Hub(clock=clock)
    conn = hub.connect()
    (reply,) = to(conn, hub.receive(conn, '{"type": "login", "name": "c", "role": "client"}'))
    assert "renewIn" not in reply
    (error,) = to(conn, hub.receive(conn, '{"type": "renew"}'))
    assert "asks for no tokens" in error["reason"]
    clock.now += 10**9
    assert hub.expire() == [] and hub.logged_in(conn)
