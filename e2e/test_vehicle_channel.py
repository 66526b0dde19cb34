"""The vehicle page against a hand-written relay in another page: bad data-channel input is
answered with errors and never breaks the vehicle; a relay leaving stops the turtle."""

from __future__ import annotations

import pytest
from playwright.sync_api import Browser, expect

from app.server.serve import RunningServer
from e2e.conftest import OpenRole

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

# A minimal relay: logs in, answers the vehicle's offer with a plain RTCPeerConnection, sends
# what it is told on the `autopilot` channel and keeps the vehicle's error replies.
FAKE_RELAY = """
async ({wsUrl, room}) => {
  const ws = new WebSocket(wsUrl);
  await new Promise((resolve) => { ws.onopen = resolve; });
  const pc = new RTCPeerConnection();
  const relay = { errors: [], channel: null, ws, timer: null };
  window.fakeRelay = relay;
  let vehicle = null;
  pc.ondatachannel = ({ channel }) => {
    channel.onmessage = (event) => {
      const msg = JSON.parse(event.data);
      if (msg.type === 'error') relay.errors.push(msg);
    };
    channel.onopen = () => { relay.channel = channel; };
  };
  pc.onicecandidate = ({ candidate }) => {
    if (!candidate) return;
    ws.send(JSON.stringify({ type: 'candidate', to: vehicle, candidate: candidate.toJSON() }));
  };
  ws.onmessage = async (event) => {
    const msg = JSON.parse(event.data);
    if (msg.type === 'offer') {
      vehicle = msg.from;
      await pc.setRemoteDescription({ type: 'offer', sdp: msg.sdp });
      await pc.setLocalDescription();
      ws.send(JSON.stringify({ type: 'answer', to: vehicle, sdp: pc.localDescription.sdp }));
    } else if (msg.type === 'candidate' && msg.candidate) {
      await pc.addIceCandidate(msg.candidate);
    }
  };
  ws.send(JSON.stringify({ type: 'login', name: 'fake-relay', role: 'relay', room }));
}
"""

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
            '{"type": "goal", "x": "left", "y": 1, "w": 640, "h": 480}',
            '{"type": "goal", "x": 1, "y": 1, "w": 0, "h": 480}',
        ]
        relay.evaluate("texts => texts.forEach((t) => window.fakeRelay.channel.send(t))", bad)
        relay.wait_for_function(f"() => window.fakeRelay.errors.length >= {len(bad)}")
        reasons = relay.evaluate("() => window.fakeRelay.errors.map((e) => e.reason)")
        assert "malformed JSON" in reasons[0]
        assert "type" in reasons[1]
        assert "warp" in reasons[2]
        assert '"x"' in reasons[3]
        assert "w, h" in reasons[4]
        expect(vehicle.get_by_test_id("goals-received")).to_have_text("0")

        # The vehicle still works: good goals are taken and turned into Twists.
        relay.evaluate(
            """goal => { window.fakeRelay.timer = setInterval(() => window.fakeRelay.channel.send(
                   JSON.stringify({ ...goal, t: Date.now() })), 100); }""",
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
