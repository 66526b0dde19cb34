"""The hub's limits (issue 9 "Hostile input"), on the sans-I/O hub with an injected clock."""

from __future__ import annotations

import json
from typing import Any

from app.protocol import tokens
from app.protocol.rooms import Role
from app.server.config import Settings
from app.signaling.hub import (
    BYTES_BURST,
    MAX_ROOM_PEERS,
    MAX_TOKEN_SESSIONS,
    RATE_BURST,
    RATE_PER_S,
    ROOM_PLACES,
    Action,
    Close,
    Hub,
    Outgoing,
)
from tests.helpers.clock import Clock


def to(conn: str, actions: list[Action]) -> list[dict[str, Any]]:
    return [a.message for a in actions if isinstance(a, Outgoing) and a.conn == conn]


def login(hub: Hub, name: str, role: str, room: str = "default") -> tuple[str, list[Action]]:
    conn = hub.connect()
    message = {"type": "login", "name": name, "role": role, "room": room}
    return conn, hub.receive(conn, json.dumps(message))


def test_a_flooding_client_is_refused_and_closed_while_the_relay_is_spared() -> None:
    clock = Clock()
    hub = Hub(clock=clock)
    relay, _ = login(hub, "r", "relay")
    client, _ = login(hub, "c", "client")
    to_relay = 0
    closed: list[Close] = []
    # 2000 stops sent in no time at all.
    for _ in range(2000):
        actions = hub.receive(client, '{"type": "stop"}')
        to_relay += sum(m["type"] == "stop" for m in to(relay, actions))
        closed += [a for a in actions if isinstance(a, Close)]
        if closed:
            break
    # The relay got the burst (less the sender's login), no more; the sender was refused and
    # then closed as abusive.
    assert to_relay == RATE_BURST - 1
    assert [c.conn for c in closed] == [client] and closed[0].code == 1008
    assert not hub.logged_in(client) and hub.logged_in(relay)


def test_the_rate_limit_refills_and_names_itself() -> None:
    clock = Clock()
    hub = Hub(clock=clock)
    relay, _ = login(hub, "r", "relay")
    client, _ = login(hub, "c", "client")
    for _ in range(RATE_BURST - 2):  # the two logins spent one token each, on their own buckets
        hub.receive(client, '{"type": "stop"}')
    refused = to(client, hub.receive(client, '{"type": "stop"}'))
    refused += to(client, hub.receive(client, '{"type": "stop"}'))
    assert refused and "rate limit" in refused[-1]["reason"]
    clock.now += 1.0  # a second later RATE_PER_S more may pass
    passed = sum(len(to(relay, hub.receive(client, '{"type": "stop"}'))) for _ in range(10))
    assert passed == 10 <= RATE_PER_S


def test_a_room_holds_a_bounded_number_of_clients() -> None:
    hub = Hub()
    for n in range(ROOM_PLACES["client"]):
        conn, actions = login(hub, f"p{n}", "client")
        assert to(conn, actions)[0]["success"] is True
    late, actions = login(hub, "late", "client")
    reply = to(late, actions)[0]
    assert reply["success"] is False and "no place" in reply["reason"]
    # Another room still takes peers.
    other, actions = login(hub, "late", "client", "elsewhere")
    assert to(other, actions)[0]["success"] is True


def test_huge_integers_and_deep_nesting_before_login_get_an_error_reply() -> None:
    hub = Hub()
    conn = hub.connect()
    for frame in ('{"type": "login", "n": ' + "9" * 5000 + "}", "[" * 3000, '{"x": NaN}'):
        (error,) = to(conn, hub.receive(conn, frame))
        assert error["type"] == "error" and error["reason"]
    reply = hub.receive(conn, '{"type": "login", "name": "c", "role": "client"}')
    assert to(conn, reply)[0]["success"] is True


def test_logged_in_reports_the_login_deadline_condition() -> None:
    hub = Hub()
    conn = hub.connect()
    assert not hub.logged_in(conn)
    hub.receive(conn, '{"type": "login", "name": "c", "role": "client"}')
    assert hub.logged_in(conn)


SECRET = "hub-limits-test-secret"


def login_with(hub: Hub, name: str, role: Role, token: str, room: str = "lab") -> dict[str, Any]:
    """Log in a new connection with ``token``; the login reply."""
    conn = hub.connect()
    message = {"type": "login", "name": name, "role": role, "room": room, "token": token}
    return to(conn, hub.receive(conn, json.dumps(message)))[0]


def token_for(role: Role, clock: Clock, room: str = "lab", n: int = 0) -> str:
    """A token for ``role``; tokens with different ``n`` differ (they expire a second apart)."""
    return tokens.sign(SECRET, room, role, now=clock.now, ttl_s=600 + n)


def test_one_client_token_cannot_fill_a_room() -> None:
    # Issue 37.5: 32 logins on one client token, and the vehicle and relay were refused.
    clock = Clock()
    hub = Hub(secret=SECRET, clock=clock)
    shared = token_for("client", clock)
    replies = [login_with(hub, f"c{n}", "client", shared) for n in range(32)]
    accepted = [r for r in replies if r["success"]]
    assert 1 <= len(accepted) == MAX_TOKEN_SESSIONS < 32
    refused = next(r for r in replies if not r["success"])
    assert f"already has {MAX_TOKEN_SESSIONS} sessions" in refused["reason"]
    assert login_with(hub, "v", "vehicle", token_for("vehicle", clock))["success"] is True
    assert login_with(hub, "r", "relay", token_for("relay", clock))["success"] is True


def test_clients_fill_only_their_own_places() -> None:
    clock = Clock()
    hub = Hub(secret=SECRET, clock=clock)
    for n in range(ROOM_PLACES["client"]):
        token = token_for("client", clock, n=n)
        assert login_with(hub, f"c{n}", "client", token)["success"] is True
    late = login_with(hub, "late", "client", token_for("client", clock, n=100))
    assert late["success"] is False
    assert late["reason"] == f"room 'lab' has no place for another client ({ROOM_PLACES['client']})"
    # Clients never take the vehicle's or the relay's place.
    assert ROOM_PLACES["client"] < MAX_ROOM_PEERS
    assert login_with(hub, "v", "vehicle", token_for("vehicle", clock))["success"] is True
    assert login_with(hub, "r", "relay", token_for("relay", clock))["success"] is True
    assert hub.census().peers == {"client": ROOM_PLACES["client"], "vehicle": 1, "relay": 1}


def test_a_room_keeps_a_place_for_one_relay_and_a_vehicle_whatever_fills_it() -> None:
    assert ROOM_PLACES["relay"] == 1 and ROOM_PLACES["vehicle"] >= 1
    assert sum(ROOM_PLACES.values()) == MAX_ROOM_PEERS
    hub = Hub()
    for role, places in ROOM_PLACES.items():
        for n in range(places):
            conn, actions = login(hub, f"{role}{n}", role)
            assert to(conn, actions)[0]["success"] is True
        conn, actions = login(hub, f"{role}-late", role)
        assert to(conn, actions)[0]["success"] is False


def test_a_candidate_has_a_sensible_size() -> None:
    hub = Hub()
    relay, _ = login(hub, "r", "relay")
    client, _ = login(hub, "c", "client")
    line = "candidate:1 1 udp 2122260223 192.168.1.20 54321 typ host generation 0 ufrag abcd"
    fine = {"type": "candidate", "to": "r", "candidate": {"candidate": line, "sdpMid": "0"}}
    assert to(relay, hub.receive(client, json.dumps(fine)))[0]["candidate"]["candidate"] == line
    padded = {**fine, "candidate": {"candidate": line + " x" * 30_000}}
    actions = hub.receive(client, json.dumps(padded))
    assert to(relay, actions) == []
    (error,) = to(client, actions)
    assert error["ref"] == "candidate" and "exceeds its limit of 4096" in error["reason"]


def test_a_sender_s_bytes_are_budgeted_so_it_never_fills_its_receiver() -> None:
    clock = Clock()
    hub = Hub(clock=clock)
    relay, _ = login(hub, "r", "relay")
    vehicle, _ = login(hub, "v", "vehicle")
    offer = json.dumps({"type": "offer", "to": "r", "sdp": "v=0 " + "x" * 60_000})
    delivered = refused = 0
    for _ in range(100):  # 6 MB of offers in no time at all
        actions = hub.receive(vehicle, offer)
        delivered += sum(len(json.dumps(m)) for m in to(relay, actions))
        refused += sum("KiB per second" in m.get("reason", "") for m in to(vehicle, actions))
        if any(isinstance(a, Close) for a in actions):
            break
    # The relay got at most the sender's burst, far inside the outbox a slow reader would fill.
    assert 0 < delivered <= BYTES_BURST < Settings().outbox_bytes / 2
    assert refused > 0 and not hub.logged_in(vehicle) and hub.logged_in(relay)


def test_the_byte_budget_refills() -> None:
    clock = Clock()
    hub = Hub(clock=clock)
    relay, _ = login(hub, "r", "relay")
    vehicle, _ = login(hub, "v", "vehicle")
    offer = json.dumps({"type": "offer", "to": "r", "sdp": "x" * 60_000})
    passed = [bool(to(relay, hub.receive(vehicle, offer))) for _ in range(6)]
    assert passed == [True] * 4 + [False] * 2  # 256 KiB of 60 KB offers
    clock.now += 1.0  # a second later 64 KiB more may pass: one offer
    assert [bool(to(relay, hub.receive(vehicle, offer))) for _ in range(2)] == [True, False]
