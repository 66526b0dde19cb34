"""Issue 9: a peer name (or any text a peer sends) must never forge a server log line."""

from __future__ import annotations

import json
import logging

import pytest

from app.signaling.hub import Hub, Outgoing

FORGED = "x\nINFO app.signaling.core: vehicle 'v' joined room 'r'"


@pytest.mark.parametrize("field", ["name", "room"])
@pytest.mark.parametrize("bad", [FORGED, "a\rb", "a\x85b", "a\u2028b", "a\x00b"])
def test_names_with_line_breaks_or_control_characters_are_refused(field: str, bad: str) -> None:
    hub = Hub()
    conn = hub.connect()
    login = {"type": "login", "name": "n", "role": "client", "room": "r", field: bad}
    replies = [a.message for a in hub.receive(conn, json.dumps(login)) if isinstance(a, Outgoing)]
    assert replies[0]["type"] == "login" and replies[0]["success"] is False
    assert "control characters or line breaks" in replies[0]["reason"]
    assert hub.rooms() == []


def test_nothing_a_peer_sends_puts_a_line_break_in_the_log(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="app.signaling")
    hub = Hub(max_errors_in_a_row=3)
    conn = hub.connect()
    hub.receive(conn, json.dumps({"type": "login", "name": "ok", "role": "client", "room": "r"}))
    for frame in (
        {"type": FORGED},
        {"type": "offer", "to": FORGED, "sdp": "x"},
        {"type": "login", "name": FORGED, "role": "client"},
    ):
        hub.receive(conn, json.dumps(frame))
    assert caplog.records, "the refusals were not logged at all"
    for record in caplog.records:
        assert "\n" not in record.getMessage(), record.getMessage()
