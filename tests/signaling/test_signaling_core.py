"""The signaling rules (docs/architecture.md, "Signaling protocol"), exercised on the sans-I/O
hub directly (no sockets)."""

from __future__ import annotations

import json
from typing import Any

import pytest

from app.protocol import tokens
from app.server.config import Settings
from app.server.signaling import Switchboard
from app.signaling.hub import Action, Close, Hub, Outgoing


class Harness:
    """A hub plus helpers to send as a connection and read what each connection was sent."""

    def __init__(self, hub: Hub | None = None) -> None:
        self.hub = hub or Hub()

    def send(self, conn: str, message: dict[str, Any] | str) -> list[Action]:
        text = message if isinstance(message, str) else json.dumps(message)
        return self.hub.receive(conn, text)

    def login(self, name: str, role: str, room: str | None = "default", **extra: Any) -> str:
        conn = self.hub.connect()
        message = {"type": "login", "name": name, "role": role, **extra}
        if room is not None:
            message["room"] = room
        reply = only(to(conn, self.send(conn, message)))
        assert reply["success"] is True, reply
        return conn


def to(conn: str, actions: list[Action]) -> list[dict[str, Any]]:
    """The messages ``actions`` deliver to ``conn``, in order."""
    return [a.message for a in actions if isinstance(a, Outgoing) and a.conn == conn]


def recipients(actions: list[Action]) -> set[str]:
    return {a.conn for a in actions if isinstance(a, Outgoing)}


def closes(actions: list[Action]) -> list[Close]:
    return [a for a in actions if isinstance(a, Close)]


def only(messages: list[dict[str, Any]]) -> dict[str, Any]:
    assert len(messages) == 1, messages
    return messages[0]


def assert_error(actions: list[Action], conn: str, ref: str | None, *words: str) -> str:
    """``conn`` got exactly one error with ``ref``, nobody else got anything; returns the reason."""
    assert recipients(actions) == {conn}, actions
    assert not closes(actions)
    error = to(conn, actions)[-1]
    assert error["type"] == "error"
    assert error["ref"] == ref
    for word in words:
        assert word in error["reason"], error
    return str(error["reason"])


@pytest.fixture
def h() -> Harness:
    return Harness()


@pytest.fixture
def triangle(h: Harness) -> tuple[str, str, str]:
    """A relay, a vehicle and a client logged in to room "default" in that order."""
    return h.login("r", "relay"), h.login("v", "vehicle"), h.login("c", "client")


# -- login and rosters ------------------------------------------------------------------------


def test_login_reply_lists_the_others_and_they_get_a_roster(h: Harness) -> None:
    relay = h.login("r", "relay", room="lab")
    vehicle = h.hub.connect()
    actions = h.send(vehicle, {"type": "login", "name": "v", "role": "vehicle", "room": "lab"})

    assert to(vehicle, actions) == [
        {
            "type": "login",
            "success": True,
            "room": "lab",
            "peers": [{"name": "r", "role": "relay"}],
            "iceServers": [],
            "iceTransportPolicy": "all",
        }
    ]
    assert to(relay, actions) == [
        {"type": "peers", "room": "lab", "peers": [{"name": "v", "role": "vehicle"}]}
    ]


def test_room_defaults_to_default(h: Harness) -> None:
    conn = h.hub.connect()
    reply = only(to(conn, h.send(conn, {"type": "login", "name": "a", "role": "client"})))
    assert reply["room"] == "default"
    assert [p.name for p in h.hub.roster("default")] == ["a"]


def test_rosters_are_in_join_order_and_leave_out_the_recipient(
    h: Harness, triangle: tuple[str, str, str]
) -> None:
    relay, vehicle, client = triangle
    newcomer = h.hub.connect()
    actions = h.send(newcomer, {"type": "login", "name": "c2", "role": "client"})

    names = {conn: [p["name"] for p in only(to(conn, actions))["peers"]] for conn in triangle}
    assert names == {relay: ["v", "c", "c2"], vehicle: ["r", "c", "c2"], client: ["r", "v", "c2"]}
    assert [p["name"] for p in only(to(newcomer, actions))["peers"]] == ["r", "v", "c"]


def test_name_taken_in_the_same_room_is_refused(h: Harness) -> None:
    h.login("v", "vehicle")
    conn = h.hub.connect()
    actions = h.send(conn, {"type": "login", "name": "v", "role": "client"})

    assert recipients(actions) == {conn}, "the room is not told about a refused login"
    reply, error = to(conn, actions)
    assert reply["type"] == "login" and reply["success"] is False
    assert "taken" in reply["reason"]
    assert error == {"type": "error", "reason": reply["reason"], "ref": "login"}
    assert [(p.name, p.role) for p in h.hub.roster("default")] == [("v", "vehicle")]


def test_same_name_in_another_room_is_fine(h: Harness) -> None:
    h.login("v", "vehicle", room="a")
    h.login("v", "vehicle", room="b")
    assert [p.name for p in h.hub.roster("b")] == ["v"]


def test_second_vehicle_in_a_room_is_refused_until_the_first_leaves(h: Harness) -> None:
    # Issue 37: a room pilots one vehicle. A second one, token or not, would take the relay's
    # video and seat; it is told at the door which vehicle the room has.
    first = h.login("v1", "vehicle", room="lab")
    conn = h.hub.connect()
    login = {"type": "login", "name": "v2", "role": "vehicle", "room": "lab"}
    actions = h.send(conn, login)
    reply = to(conn, actions)[0]
    assert reply["success"] is False and "'v1'" in reply["reason"], reply
    assert_error(actions, conn, "login", "vehicle", "'v1'")
    assert [p.name for p in h.hub.roster("lab")] == ["v1"]
    h.login("v2", "vehicle", room="other")
    h.send(first, {"type": "leave"})
    h.login("v2", "vehicle", room="lab")


def test_second_relay_in_a_room_is_refused_but_fine_in_another_room(h: Harness) -> None:
    h.login("r1", "relay")
    conn = h.hub.connect()
    actions = h.send(conn, {"type": "login", "name": "r2", "role": "relay"})
    reply = to(conn, actions)[0]
    assert reply["success"] is False and "relay" in reply["reason"]
    assert_error(actions, conn, "login", "relay")

    h.login("r2", "relay", room="other")


def test_refused_login_can_be_retried_on_the_same_connection(h: Harness) -> None:
    h.login("v", "vehicle")
    conn = h.hub.connect()
    h.send(conn, {"type": "login", "name": "v", "role": "client"})  # the name is taken
    reply = to(conn, h.send(conn, {"type": "login", "name": "c", "role": "client"}))[0]
    assert reply["success"] is True


@pytest.mark.parametrize("role", ["pilot", "", "RELAY"])
def test_bad_role_is_refused(h: Harness, role: str) -> None:
    conn = h.hub.connect()
    actions = h.send(conn, {"type": "login", "name": "x", "role": role})
    reply = to(conn, actions)[0]
    assert reply["type"] == "login" and reply["success"] is False
    assert "role" in reply["reason"]
    assert_error(actions, conn, "login", "role")
    assert h.hub.roster("default") == []


SECRET = "signaling-core-test-secret"
NOW = 1_800_000_000.0


def _signed(room: str, role: tokens.Role, now: float = NOW) -> str:
    return tokens.sign(SECRET, room, role, now=now, ttl_s=60)


@pytest.mark.parametrize(
    ("token", "words"),
    [
        (None, "missing token"),
        ("", "malformed"),
        ("wrong", "malformed"),
        (_signed("lab", "client"), "wrong role"),  # a client token does not make a relay
        (_signed("other", "relay"), "wrong room"),
        (_signed("lab", "relay", now=NOW - 120), "expired"),
        (tokens.sign("not-the-servers-secret", "lab", "relay", now=NOW), "bad signature"),
    ],
)
def test_login_needs_a_token_for_its_room_and_role(token: str | None, words: str) -> None:
    h = Harness(Hub(secret=SECRET, clock=lambda: NOW))
    conn = h.hub.connect()
    message: dict[str, Any] = {"type": "login", "name": "r", "role": "relay", "room": "lab"}
    if token is not None:
        message["token"] = token
    actions = h.send(conn, message)
    reply = to(conn, actions)[0]
    assert reply["success"] is False and words in reply["reason"]
    assert_error(actions, conn, "login", words)
    assert h.hub.rooms() == []


def test_a_relay_token_for_the_room_takes_the_relay_role() -> None:
    h = Harness(Hub(secret=SECRET, clock=lambda: NOW))
    h.login("r", "relay", room="lab", token=_signed("lab", "relay"))
    assert [p.role for p in h.hub.roster("lab")] == ["relay"]


def test_a_squatter_without_a_relay_token_cannot_take_the_relay_role() -> None:
    # Issue 9: whoever logged in first as relay got the vehicle's offer.
    h = Harness(Hub(secret=SECRET, clock=lambda: NOW))
    squatter = h.hub.connect()
    h.send(squatter, {"type": "login", "name": "relay", "role": "relay", "room": "lab"})
    client = h.hub.connect()
    forged = {"type": "login", "name": "relay", "role": "relay", "room": "lab"}
    h.send(client, {**forged, "token": _signed("lab", "client")})
    h.login("relay", "relay", room="lab", token=_signed("lab", "relay"))
    assert [(p.name, p.role) for p in h.hub.roster("lab")] == [("relay", "relay")]


def test_hub_from_settings_enforces_tokens_and_size() -> None:
    hub = Switchboard.from_settings(Settings(secret=SECRET, max_message_bytes=1000)).hub
    assert hub.secret == SECRET and hub.max_message_bytes == 1000


def test_login_twice_is_an_error_and_the_first_login_stands(
    h: Harness, triangle: tuple[str, str, str]
) -> None:
    relay, _, client = triangle
    actions = h.send(client, {"type": "login", "name": "other", "role": "relay"})
    assert_error(actions, client, "login", "already logged in")
    assert only(to(relay, h.send(client, {"type": "getOps"})))["from"] == "c"


# -- relaying ---------------------------------------------------------------------------------


def test_offer_goes_to_its_target_only_with_the_sender_stamped(
    h: Harness, triangle: tuple[str, str, str]
) -> None:
    relay, vehicle, _ = triangle
    offer = {"type": "offer", "to": "r", "sdp": "v=0\r\n", "from": "c", "extra": [1, 2]}
    actions = h.send(vehicle, offer)
    # The peer's own "from" is not trusted; its extra fields travel as sent.
    assert actions == [Outgoing(relay, {**offer, "from": "v"})]


def test_answer_from_the_relay_reaches_the_vehicle(
    h: Harness, triangle: tuple[str, str, str]
) -> None:
    relay, vehicle, _ = triangle
    actions = h.send(relay, {"type": "answer", "to": "v", "sdp": "v=0\r\n"})
    assert actions == [
        Outgoing(vehicle, {"type": "answer", "to": "v", "sdp": "v=0\r\n", "from": "r"})
    ]


@pytest.mark.parametrize(
    "candidate", [{"candidate": "candidate:1 1 udp 1 10.0.0.1 9 typ host", "sdpMid": "0"}, None]
)
def test_candidates_flow_both_ways_including_end_of_candidates(
    h: Harness, triangle: tuple[str, str, str], candidate: dict[str, Any] | None
) -> None:
    relay, _, client = triangle
    forth = h.send(client, {"type": "candidate", "to": "r", "candidate": candidate})
    back = h.send(relay, {"type": "candidate", "to": "c", "candidate": candidate})
    assert only(to(relay, forth)) == {
        "type": "candidate",
        "to": "r",
        "candidate": candidate,
        "from": "c",
    }
    assert only(to(client, back))["from"] == "r"
    assert recipients(forth) == {relay} and recipients(back) == {client}


@pytest.mark.parametrize("kind", ["start", "stop", "getOps"])
def test_client_commands_go_to_the_rooms_relay(
    h: Harness, triangle: tuple[str, str, str], kind: str
) -> None:
    relay, _, client = triangle
    actions = h.send(client, {"type": kind, "from": "r"})
    assert actions == [Outgoing(relay, {"type": kind, "from": "c"})]


@pytest.mark.parametrize(
    ("sender", "message"),
    [
        ("r", {"type": "offer", "to": "v", "sdp": "x"}),
        ("c", {"type": "answer", "to": "r", "sdp": "x"}),
        ("v", {"type": "answer", "to": "r", "sdp": "x"}),
        ("v", {"type": "start"}),
        ("v", {"type": "stop"}),
        ("r", {"type": "getOps"}),
    ],
)
def test_a_role_sending_what_it_may_not_gets_an_error(
    h: Harness, triangle: tuple[str, str, str], sender: str, message: dict[str, Any]
) -> None:
    conn = dict(zip(("r", "v", "c"), triangle, strict=True))[sender]
    assert_error(h.send(conn, message), conn, message["type"], "may only be sent by")


@pytest.mark.parametrize("kind", ["start", "stop", "getOps"])
def test_client_commands_without_a_relay_are_an_error(h: Harness, kind: str) -> None:
    h.login("v", "vehicle")
    client = h.login("c", "client")
    assert_error(h.send(client, {"type": kind}), client, kind, "no relay")


@pytest.mark.parametrize("kind", ["offer", "candidate"])
def test_to_naming_nobody_is_an_error(
    h: Harness, triangle: tuple[str, str, str], kind: str
) -> None:
    _, vehicle, _ = triangle
    message = {"type": kind, "to": "ghost", "sdp": "x", "candidate": None}
    assert_error(h.send(vehicle, message), vehicle, kind, "ghost")


def test_to_oneself_is_an_error(h: Harness, triangle: tuple[str, str, str]) -> None:
    _, vehicle, _ = triangle
    message = {"type": "candidate", "to": "v", "candidate": None}
    assert_error(h.send(vehicle, message), vehicle, "candidate", "yourself")


# -- leaving ----------------------------------------------------------------------------------


def test_leave_tells_the_others_then_closes_the_sender(
    h: Harness, triangle: tuple[str, str, str]
) -> None:
    relay, vehicle, client = triangle
    actions = h.send(vehicle, {"type": "leave", "from": "r"})

    for other, roster in ((relay, ["c"]), (client, ["r"])):
        leave, peers = to(other, actions)
        assert leave == {"type": "leave", "from": "v"}
        assert [p["name"] for p in peers["peers"]] == roster
    assert to(vehicle, actions) == []
    assert closes(actions) == [Close(vehicle, 1000, "left")]
    assert isinstance(actions[-1], Close), "the close comes after the notifications"
    assert h.send(vehicle, {"type": "getOps"}) == [], "a leaving connection is not served"
    assert h.hub.disconnect(vehicle) == [], "the room is not told twice"


def test_closed_socket_counts_as_leave(h: Harness, triangle: tuple[str, str, str]) -> None:
    relay, vehicle, client = triangle
    actions = h.hub.disconnect(client)
    assert to(relay, actions)[0] == {"type": "leave", "from": "c"}
    assert to(vehicle, actions)[0] == {"type": "leave", "from": "c"}
    assert not closes(actions)
    assert [p.name for p in h.hub.roster("default")] == ["r", "v"]


def test_disconnect_before_login_tells_nobody(h: Harness, triangle: tuple[str, str, str]) -> None:
    assert h.hub.disconnect(h.hub.connect()) == []


@pytest.mark.parametrize("how", ["leave", "close"])
def test_same_name_and_relay_slot_are_free_again_after_leaving(h: Harness, how: str) -> None:
    relay = h.login("r", "relay")
    client = h.login("c", "client")
    if how == "leave":
        h.send(relay, {"type": "leave"})
    h.hub.disconnect(relay)

    again = h.hub.connect()
    actions = h.send(again, {"type": "login", "name": "r", "role": "relay"})
    assert to(again, actions)[0]["success"] is True
    assert only(to(client, actions))["type"] == "peers"
    assert only(to(again, h.send(client, {"type": "getOps"})))["from"] == "c"


def test_last_peer_leaving_empties_the_room(h: Harness) -> None:
    conn = h.login("a", "client", room="brief")
    assert h.hub.rooms() == ["brief"]
    h.hub.disconnect(conn)
    assert h.hub.rooms() == []
    h.login("a", "relay", room="brief")


def test_refused_logins_leave_no_rooms_behind() -> None:
    h = Harness(Hub(secret=SECRET))
    for n in range(5):
        conn = h.hub.connect()
        h.send(conn, {"type": "login", "name": "x", "role": "client", "room": f"r{n}"})
    assert h.hub.rooms() == []


# -- rooms ------------------------------------------------------------------------------------


def test_rooms_are_isolated(h: Harness) -> None:
    a = {role: h.login(name, role, room="a") for name, role in (("r", "relay"), ("c", "client"))}
    b = {role: h.login(name, role, room="b") for name, role in (("r", "relay"), ("c", "client"))}

    # Same names in both rooms: each message reaches its own room's peer only.
    assert recipients(h.send(a["client"], {"type": "offer", "to": "r", "sdp": "a"})) == {a["relay"]}
    assert recipients(h.send(b["client"], {"type": "getOps"})) == {b["relay"]}
    left = h.send(a["client"], {"type": "leave"})
    assert recipients(left) == {a["relay"]}
    assert [p.name for p in h.hub.roster("b")] == ["r", "c"]


def test_a_peer_in_another_room_is_nobody(h: Harness) -> None:
    h.login("r", "relay", room="a")
    vehicle = h.login("v", "vehicle", room="b")
    assert_error(
        h.send(vehicle, {"type": "offer", "to": "r", "sdp": "x"}), vehicle, "offer", "room 'b'"
    )


# -- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "ref", "words"),
    [
        ("{not json", None, ["malformed JSON"]),
        ("", None, ["malformed JSON"]),
        ("[" * 50_000, None, ["malformed JSON"]),
        ("[1, 2]", None, ["object", "list"]),
        ("42", None, ["object"]),
        ('"login"', None, ["object"]),
        ("null", None, ["object"]),
        ("{}", None, ["type"]),
        ('{"type": 3}', None, ["type"]),
        ('{"type": "teleport"}', "teleport", ["unknown", "teleport"]),
        ('{"type": "offer", "to": "r"}', "offer", ["sdp", "required"]),
        ('{"type": "offer", "to": "r", "sdp": 5}', "offer", ["sdp", "string"]),
        ('{"type": "answer", "sdp": "x"}', "answer", ["to"]),
        ('{"type": "offer", "to": "", "sdp": "x"}', "offer", ["to"]),
        ('{"type": "candidate", "to": "r"}', "candidate", ["candidate"]),
        ('{"type": "candidate", "to": "r", "candidate": "a=x"}', "candidate", ["candidate"]),
        ('{"type": "candidate", "to": ["r"], "candidate": null}', "candidate", ["to"]),
    ],
)
def test_malformed_messages_get_an_error_naming_the_problem(
    h: Harness, triangle: tuple[str, str, str], text: str, ref: str | None, words: list[str]
) -> None:
    relay, vehicle, _ = triangle
    assert_error(h.send(vehicle, text), vehicle, ref, *words)
    # The connection stays open and working.
    assert recipients(h.send(vehicle, {"type": "offer", "to": "r", "sdp": "x"})) == {relay}


@pytest.mark.parametrize(
    ("message", "words"),
    [
        ({"type": "login", "role": "client"}, ["name"]),
        ({"type": "login", "name": 7, "role": "client"}, ["name", "string"]),
        ({"type": "login", "name": "a", "role": "client", "room": ""}, ["room"]),
        ({"type": "login", "name": "a" * 65, "role": "client"}, ["name"]),
        ({"type": "login", "name": "a", "role": "client", "token": 1}, ["token"]),
    ],
)
def test_malformed_login_is_a_refused_login(
    h: Harness, message: dict[str, Any], words: list[str]
) -> None:
    conn = h.hub.connect()
    actions = h.send(conn, message)
    assert to(conn, actions)[0]["success"] is False
    assert_error(actions, conn, "login", *words)


@pytest.mark.parametrize(
    "message",
    [
        {"type": "offer", "to": "r", "sdp": "x"},
        {"type": "answer", "to": "r", "sdp": "x"},
        {"type": "candidate", "to": "r", "candidate": None},
        {"type": "start"},
        {"type": "stop"},
        {"type": "getOps"},
        {"type": "leave"},
    ],
)
def test_messages_before_login_are_an_error(h: Harness, message: dict[str, Any]) -> None:
    relay = h.login("r", "relay")
    conn = h.hub.connect()
    actions = h.send(conn, message)
    assert_error(actions, conn, message["type"], "log in")
    assert relay not in recipients(actions)


def test_oversize_message_is_refused_without_parsing_and_the_connection_works(
    h: Harness, triangle: tuple[str, str, str]
) -> None:
    relay, _, client = triangle
    limit = h.hub.max_message_bytes
    padding = "x" * limit
    reason = assert_error(
        h.send(client, {"type": "offer", "to": "r", "sdp": padding}), client, None, str(limit)
    )
    assert "bytes" in reason
    assert recipients(h.send(client, {"type": "offer", "to": "r", "sdp": "x"})) == {relay}


def test_size_limit_counts_utf8_bytes_and_allows_exactly_the_limit(h: Harness) -> None:
    relay = h.login("r", "relay")
    client = h.login("c", "client")
    limit = h.hub.max_message_bytes
    empty = json.dumps({"type": "offer", "to": "r", "sdp": ""}, ensure_ascii=False)
    at_limit = json.dumps(
        {"type": "offer", "to": "r", "sdp": "x" * (limit - len(empty))}, ensure_ascii=False
    )
    assert len(at_limit.encode()) == limit
    assert recipients(h.send(client, at_limit)) == {relay}

    # Fewer characters than the limit, but two bytes each in UTF-8.
    wide = json.dumps({"type": "offer", "to": "r", "sdp": "é" * (limit // 2)}, ensure_ascii=False)
    assert len(wide) < limit < len(wide.encode())
    assert_error(h.send(client, wide), client, None, "bytes")


def test_binary_frames_are_refused(h: Harness, triangle: tuple[str, str, str]) -> None:
    _, vehicle, _ = triangle
    actions = h.hub.receive_binary(vehicle)
    assert_error(actions, vehicle, None, "binary")


def test_an_abusive_peer_is_closed_and_its_room_told(
    h: Harness, triangle: tuple[str, str, str]
) -> None:
    relay, vehicle, _ = triangle
    limit = h.hub.max_errors_in_a_row
    for _ in range(limit - 1):
        assert not closes(h.send(vehicle, "garbage"))
    actions = h.send(vehicle, "garbage")
    assert to(vehicle, actions)[0]["type"] == "error"
    (close,) = closes(actions)
    assert close.conn == vehicle and close.code == 1008 and "abusive" in close.reason
    assert to(relay, actions)[0] == {"type": "leave", "from": "v"}
    assert [p.name for p in h.hub.roster("default")] == ["r", "c"]
    assert h.send(vehicle, {"type": "getOps"}) == []


def test_a_good_message_resets_the_abuse_count(h: Harness, triangle: tuple[str, str, str]) -> None:
    relay, vehicle, _ = triangle
    limit = h.hub.max_errors_in_a_row
    for _ in range(3):
        for _ in range(limit - 1):
            assert not closes(h.send(vehicle, "garbage"))
        assert recipients(h.send(vehicle, {"type": "offer", "to": "r", "sdp": "x"})) == {relay}


def test_abuse_before_login_closes_the_connection(h: Harness) -> None:
    conn = h.hub.connect()
    actions: list[Action] = []
    for _ in range(h.hub.max_errors_in_a_row):
        actions = h.hub.receive_binary(conn)
    assert [c.code for c in closes(actions)] == [1008]
