"""The operator's console end to end (browser vehicle, relay page, two client pages): the link
health panel measures both links; a client takes the wheel and turns the turtle with ArrowLeft
against the autopilot's pull, a release stops it; a second client sees who drives and is refused
the wheel; after Hand Back it drives with a (stubbed) gamepad; the vehicle's dead-man stops the
turtle when that client goes silent, and its leaving gives the wheel back with piloting stopped.
"""

from __future__ import annotations

import math
import time
from typing import Any

import pytest
from playwright.sync_api import Browser, Page, expect

from app.server.serve import RunningServer
from e2e.conftest import OpenRole, open_room
from e2e.helpers import ccw_from, heading_error, status, stopped, theta, wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]

# A gamepad in the W3C standard mapping that the test holds: navigator.getGamepads() returns it.
GAMEPAD_STUB = """
window.stubPad = {
  id: 'stub', index: 0, connected: true, mapping: 'standard', timestamp: 0,
  axes: [0, 0, 0, 0],
  buttons: Array.from({ length: 17 }, () => ({ pressed: false, touched: false, value: 0 })),
};
navigator.getGamepads = () => [window.stubPad];
"""
# Left shoulder held (the enable button) and the left stick pushed left, or all let go.
PAD_LEFT = "() => { stubPad.buttons[4].pressed = true; stubPad.axes[0] = -1; }"
PAD_RELEASED = "() => { stubPad.buttons[4].pressed = false; stubPad.axes[0] = 0; }"
# On the vehicle page, on its own clock: when it last applied a drive command, and when the zero
# Twist that followed was published (its status object's fields, watched as the page sets them).
# Beside them, how late the page's own timers run then: a probe timer set for 0.3 s after each
# command, as the dead-man's is, says how late it fired (a page starved of CPU by the suite runs
# every timer late, the dead-man's too).
WATCH_THE_DEAD_MAN = """() => {
  const status = window.autopilotStatus;
  const seen = (window.deadMan = { lastDrive: null, stopped: null, timerLate: null });
  let drives = status.drivesApplied;
  let twist = status.lastTwist;
  let probe = null;
  Object.defineProperty(status, 'drivesApplied', {
    get: () => drives,
    set: (value) => {
      drives = value;
      const at = (seen.lastDrive = performance.now());
      seen.stopped = null;
      clearTimeout(probe);
      probe = setTimeout(() => (seen.timerLate = performance.now() - at - 300), 300);
    },
  });
  Object.defineProperty(status, 'lastTwist', {
    get: () => twist,
    set: (value) => {
      twist = value;
      const zero = value.linear === 0 && value.angular === 0;
      if (zero && seen.stopped === null) seen.stopped = performance.now();
    },
  });
}"""


def healthy(client: Page) -> bool:
    """Both links measured with plausible figures, and a recent goal at the vehicle."""
    health = client.evaluate("() => structuredClone(window.autopilotHealth)")
    # The relay passes the vehicle's frames through to the client as they came (its Chromium
    # has encoded transforms): the same size on both links (net/video-forward.js).
    for link, size in (
        (health["vehicleToRelay"], (640, 480)),
        (health["relayToClient"], (640, 480)),
    ):
        if link is None or link["fps"] is None or link["fps"] <= 0 or link["rttMs"] is None:
            return False
        assert link["candidate"] == "host" and (link["width"], link["height"]) == size
        assert 0 <= link["lossPct"] <= 100 and 0 <= link["rttMs"] < 10_000
    age = health["goalAgeMs"]
    return age is not None and 0 <= age < 2000


def turns_left_then_stops(server: RunningServer, vehicle: Page, press: Any, release: Any) -> None:
    start = theta(server)
    press()
    wait_until(lambda: ccw_from(start, theta(server)) > math.radians(60), 20, "a left turn")
    release()
    wait_until(lambda: stopped(vehicle), 10, "a zero Twist once let go")
    held = theta(server)
    time.sleep(1.0)
    assert theta(server) == pytest.approx(held, abs=1e-9), "the turtle moved after the release"


def test_take_over_drive_refuse_a_second_operator_hand_back_and_the_dead_man(
    server: RunningServer, open_role: OpenRole, browser: Browser, vehicle_browser: Browser
) -> None:
    vehicle, _, ann = open_room(open_role, "wheel", vehicle_browser, browser, "ann")
    bob = open_role("client", browser, init_script=GAMEPAD_STUB, room="wheel", name="bob", auto="1")

    start = ann.get_by_role("button", name="Start Piloting")
    expect(start).to_be_enabled(timeout=120_000)
    start.click()
    wait_until(lambda: heading_error(theta(server), math.pi) < 0.3, 60, "the autopilot's turn")

    # The link health panel: both links measured, on loopback host candidates with no loss
    # warning, and the vehicle's last goal a moment ago while the autopilot steers.
    wait_until(lambda: healthy(ann), 30, "both links measured")
    health = ann.evaluate("() => structuredClone(window.autopilotHealth)")
    assert health["warnings"] == [], health
    video_cell = ann.get_by_test_id("health-vehicle").locator("td").nth(2)
    assert video_cell.inner_text().endswith("640×480")

    ann.get_by_role("button", name="Take Over").click()
    expect(ann.get_by_test_id("mode")).to_contain_text("you drive")
    expect(vehicle.get_by_test_id("mode")).to_have_text("manual: ann")
    # The face pulls the turtle to θ ≈ π; ArrowLeft turns it on, counter-clockwise, past that.
    keyboard = ann.keyboard
    turns_left_then_stops(
        server, vehicle, lambda: keyboard.down("ArrowLeft"), lambda: keyboard.up("ArrowLeft")
    )
    # The relay still pilots: its goals reach the vehicle and are dropped, recorded as the
    # agent records them, and none of them steers.
    dropped = status(vehicle)["goalsDropped"]["manual"]
    wait_until(
        lambda: status(vehicle)["goalsDropped"]["manual"] > dropped, 10, "goals dropped (manual)"
    )
    records = status(vehicle)["records"]
    last = next(r for r in reversed(records) if r["ev"] == "goal_dropped")
    assert last["why"] == "manual" and isinstance(last["seq"], int), last
    # Since ann took the wheel (or as far back as the page keeps), no goal was applied.
    taken = max((i for i, r in enumerate(records) if r["ev"] == "mode"), default=-1)
    if taken >= 0:
        assert records[taken]["mode"] == "manual", records[taken]
    assert not any(r["ev"] == "goal" for r in records[taken + 1 :]), records

    # Bob sees who drives and cannot take over: the button is off, and the relay refuses.
    expect(bob.get_by_test_id("mode")).to_have_text("ann is driving")
    take_bob = bob.get_by_role("button", name="Take Over")
    expect(take_bob).to_be_disabled()
    take_bob.evaluate("(button) => { button.disabled = false; }")
    take_bob.click()
    expect(bob.get_by_test_id("log")).to_contain_text("ann is driving; take over once")
    expect(vehicle.get_by_test_id("mode")).to_have_text("manual: ann")

    ann.get_by_role("button", name="Hand Back").click()
    expect(ann.get_by_test_id("mode")).to_have_text("autopilot steers")
    wait_until(lambda: heading_error(theta(server), math.pi) < 0.3, 30, "the autopilot again")

    take_bob.click()
    expect(bob.get_by_test_id("mode")).to_contain_text("you drive")
    expect(ann.get_by_test_id("mode")).to_have_text("bob is driving")
    turns_left_then_stops(
        server, vehicle, lambda: bob.evaluate(PAD_LEFT), lambda: bob.evaluate(PAD_RELEASED)
    )

    # Bob holds the stick, then his page goes silent (paused: no more commands, no release):
    # the vehicle's dead-man stops the turtle 0.3 s after the last command it applied (the
    # contract, docs/contracts.md; 0.05 s for the page's timer and however late the probe timer
    # beside it fired, 0.01 s for the command being counted a moment before it is watched), with
    # bob still at the wheel.
    vehicle.evaluate(WATCH_THE_DEAD_MAN)
    bob.evaluate(PAD_LEFT)
    wait_until(lambda: not stopped(vehicle), 10, "bob's gamepad turning the turtle")
    cdp = bob.context.new_cdp_session(bob)
    cdp.send("Debugger.enable")
    cdp.send("Debugger.pause")  # the page's script stops at its next step: the repeat timer's
    wait_until(lambda: stopped(vehicle), 5, "the dead-man's zero Twist")
    dead_man = vehicle.evaluate("() => window.deadMan")
    stopped_after = (dead_man["stopped"] - dead_man["lastDrive"]) / 1000
    late = max(0.0, dead_man["timerLate"]) / 1000
    assert 0.3 - 0.01 <= stopped_after <= 0.3 + 0.05 + late, dead_man
    assert status(vehicle)["mode"] == "manual"
    held = theta(server)
    time.sleep(1.0)
    assert theta(server) == pytest.approx(held, abs=1e-9)

    # Bob's link drops for good: the wheel goes back, with piloting stopped.
    bob.close()
    expect(ann.get_by_test_id("mode")).to_have_text("autopilot steers", timeout=30_000)
    expect(vehicle.get_by_test_id("mode")).to_have_text("autopilot")
    expect(start).to_be_enabled()
