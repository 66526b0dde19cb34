"""The hub's limits (issue 9 "Hostile input"), on the sans-I/O hub with an injected clock."""

from __future__ import annotations

import json
from typing import Any

from app.signaling.hub import (
    MAX_ROOM_PEERS,
    RATE_BURST,
    RATE_PER_S,
    Action,
    Close,
    Hub,
    Outgoing,
)


class Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


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


def test_a_room_holds_a_bounded_number_of_peers() -> None:
    hub = Hub()
    for n in range(MAX_ROOM_PEERS):
        conn, actions = login(hub, f"p{n}", "client")
        assert to(conn, actions)[0]["success"] is True
    late, actions = login(hub, "late", "client")
    reply = to(late, actions)[0]
    assert reply["success"] is False and "full" in reply["reason"]
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
