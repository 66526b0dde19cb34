"""The vehicle page against a hand-written relay in another page: bad data-channel input is
answered with errors and never breaks the vehicle; a relay leaving stops the turtle."""

from __future__ import annotations

import json

import pytest
from playwright.sync_api import Browser, expect

from app.server.serve import RunningServer
from e2e.conftest import OpenRole
from e2e.helpers import FAKE_RELAY

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

GOAL = {"type": "goal", "seq": 1, "op": "face", "x": 100, "y": 240, "w": 640, "h": 480, "t": 0}


def test_vehicle_answers_bad_messages_with_errors_and_stops_when_the_relay_leaves(
    server: RunningServer, open_role: OpenRole, browser: Browser, vehicle_browser: Browser
) -> None:
    vehicle = open_role("vehicle", vehicle_browser, room="bad", name="vehicle", auto="1")
    relay = browser.new_page()
    try:
        relay.goto(server.url + "/")
        relay.evaluate(FAKE_RELAY, {"wsUrl": server.ws_url, "room": "bad"})
        relay.wait_for_function("() => window.fakeRelay.channel !== null", timeout=60_000)

        bad = [
            "not json {",
            "[1, 2]",
            '{"type": "warp"}',
            json.dumps({**GOAL, "x": "left"}),
            json.dumps({**GOAL, "w": 0}),
            json.dumps({k: v for k, v in GOAL.items() if k != "seq"}),
            json.dumps(GOAL).replace('"y": 240', '"y": NaN'),
        ]
        relay.evaluate("texts => texts.forEach((t) => window.fakeRelay.channel.send(t))", bad)
        relay.wait_for_function(f"() => window.fakeRelay.errors.length >= {len(bad)}")
        errors = relay.evaluate("() => window.fakeRelay.errors")
        reasons = [e["reason"] for e in errors]
        assert "malformed JSON" in reasons[0]
        assert "type" in reasons[1]
        assert "warp" in reasons[2] and errors[2]["ref"] == "warp"
        # A message that breaks the Goal model is refused naming the field (schema.js, from
        # the same pydantic model the Python agent validates with).
        assert 'field "x"' in reasons[3] and errors[3]["ref"] == "goal"
        assert 'field "w"' in reasons[4]
        assert 'field "seq"' in reasons[5] and "required" in reasons[5]
        assert "malformed JSON" in reasons[6]
        expect(vehicle.get_by_test_id("goals-received")).to_have_text("0")

        # The vehicle still works: good goals are taken and turned into Twists.
        relay.evaluate(
            """goal => { let seq = goal.seq;
                       window.fakeRelay.timer = setInterval(() => window.fakeRelay.channel.send(
                   JSON.stringify({ ...goal, seq: seq++, t: Date.now() })), 100); }""",
            GOAL,
        )
        vehicle.wait_for_function(
            "() => window.autopilotStatus.twistsPublished > 0"
            " && window.autopilotStatus.lastTwist.angular !== 0",
            timeout=30_000,
        )

        # The relay leaves while goals are still coming: the vehicle publishes a zero Twist
        # at once, and says why.
        relay.evaluate(
            """() => { clearInterval(window.fakeRelay.timer);
                       window.fakeRelay.ws.send(JSON.stringify({ type: 'leave' })); }"""
        )
        expect(vehicle.get_by_test_id("log")).to_contain_text("zero Twist: relay fake-relay left")
        assert vehicle.evaluate("() => window.autopilotStatus.lastTwist.angular") == 0
    finally:
        relay.close()
