"""Stop robot and no driving unwatched, end to end (browser vehicle, relay page, client pages).

A second client's Stop robot stops a turtle the operator is driving: a zero Twist at the vehicle,
the turtle stands although the operator still holds the key, piloting is off, the wheel is back
with the autopilot, and both clients say who pressed it. Then the autopilot drives only while a
client watches: piloting goes on while one client of two leaves, and stops when the last one's
link drops (its peer connection closed, its page still in the room), when its page crashes and
when it closes; a client that comes later, or whose link comes back, sees piloting off, and why.
"""

from __future__ import annotations

import json
import math
import time

import pytest
from playwright.sync_api import Browser, Page, expect

from app.server.serve import RunningServer
from e2e.conftest import OpenRole, open_room
from e2e.helpers import (
    ccw_from,
    heading_error,
    status,
    stopped,
    theta,
    turtle_state,
    wait_until,
)

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]

ROOM = "stop"
# Keeps the page's peer connections within reach, so that the test can drop its link to the
# relay (close it) while the page stays in the room.
KEEP_PEER_CONNECTIONS = """
window.peerConnections = [];
const Native = window.RTCPeerConnection;
window.RTCPeerConnection = class extends Native {
  constructor(...args) {
    super(...args);
    window.peerConnections.push(this);
  }
};
"""


def piloting(relay: Page) -> bool:
    return bool(status(relay)["piloting"])


def start_piloting(client: Page, relay: Page) -> None:
    start = client.get_by_role("button", name="Start Piloting")
    expect(start).to_be_enabled(timeout=120_000)
    start.click()
    wait_until(lambda: piloting(relay), 30, "piloting started")


def stops_heard(vehicle: Page) -> int:
    """How many of the relay's stops the vehicle page has heard (whether or not it had a goal
    to zero: on a loaded machine the goal may have timed out already)."""
    return int(status(vehicle)["stopsHeard"])


def stopped_unwatched(relay: Page, vehicle: Page, before: int, who: str) -> None:
    """Piloting stopped because nobody watched (``who``'s going), and the vehicle heard it
    (``before``: how many stops it had heard by then)."""
    wait_until(lambda: not piloting(relay), 30, f"piloting stopped once {who} went")
    stop = status(relay)["stopped"]
    assert stop["by"] is None and "no client is watching" in stop["reason"], stop
    assert who in stop["reason"], stop
    wait_until(lambda: stops_heard(vehicle) > before, 10, "the vehicle told to stop")


def crash(browser: Browser, page: Page, url_part: str) -> None:
    """Crash ``page``'s renderer (its URL holds ``url_part``), as CDP's Page.crash does. Sent
    through the browser's session: the page's own would wait forever for an answer."""
    cdp = browser.new_browser_cdp_session()
    targets = cdp.send("Target.getTargets")["targetInfos"]
    target = next(t for t in targets if t["type"] == "page" and url_part in t["url"])
    attached = cdp.send("Target.attachToTarget", {"targetId": target["targetId"], "flatten": False})
    message = {
        "sessionId": attached["sessionId"],
        "message": json.dumps({"id": 1, "method": "Page.crash"}),
    }
    with page.expect_event("crash", timeout=10_000):
        cdp.send("Target.sendMessageToTarget", message)
    cdp.detach()


def join(open_role: OpenRole, browser: Browser, name: str) -> Page:
    client = open_role(
        "client", browser, init_script=KEEP_PEER_CONNECTIONS, room=ROOM, name=name, auto="1"
    )
    expect(client.get_by_role("button", name="Stop robot")).to_be_enabled(timeout=60_000)
    return client


def test_a_second_client_stops_the_operator_and_nothing_drives_unwatched(
    server: RunningServer, open_role: OpenRole, browser: Browser, vehicle_browser: Browser
) -> None:
    vehicle, relay, ann = open_room(open_role, ROOM, vehicle_browser, browser, "ann")
    bob = join(open_role, browser, "bob")
    start_piloting(ann, relay)
    wait_until(lambda: heading_error(theta(server), math.pi) < 0.3, 60, "the autopilot's turn")

    # Ann drives: ArrowLeft held turns the turtle on, counter-clockwise.
    ann.get_by_role("button", name="Take Over").click()
    expect(ann.get_by_test_id("mode")).to_contain_text("you drive")
    ann.keyboard.down("ArrowLeft")
    turned_from = theta(server)
    wait_until(lambda: ccw_from(turned_from, theta(server)) > 0.5, 20, "ann turning the turtle")

    bob.get_by_role("button", name="Stop robot").click()
    wait_until(lambda: stopped(vehicle), 10, "a zero Twist at the vehicle")
    # The simulator applies it on its next tick (late on a loaded machine); from then on the
    # turtle stands, although Ann still holds the key: her wheel went back to the autopilot.
    wait_until(lambda: turtle_state(server)["angular_velocity"] == 0, 10, "the turtle stopping")
    held = theta(server)
    time.sleep(1.0)
    assert theta(server) == pytest.approx(held, abs=1e-9), "the turtle moved after Stop robot"
    assert stopped(vehicle) and not piloting(relay)
    for client in (ann, bob):
        expect(client.get_by_test_id("stop-state")).to_have_text("Robot stopped by bob")
        expect(client.get_by_test_id("state")).to_contain_text("not piloting")
        expect(client.get_by_test_id("mode")).to_have_text("autopilot steers")
        expect(client.get_by_test_id("log")).to_contain_text("Stop robot pressed by bob")
    expect(vehicle.get_by_test_id("mode")).to_have_text("autopilot")
    ann.keyboard.up("ArrowLeft")

    # Piloting again, then ann leaves: bob still watches, and piloting goes on.
    start_piloting(bob, relay)
    expect(ann.get_by_test_id("stop-state")).to_have_text("")
    ann.close()
    wait_until(lambda: status(relay)["clients"] == ["bob"], 30, "the relay seeing ann gone")
    time.sleep(0.5)
    assert piloting(relay) and status(relay)["watchers"] == ["bob"]

    # Bob's link to the relay drops (his page stays in the room): nobody watches.
    before = stops_heard(vehicle)
    bob.evaluate("() => window.peerConnections.forEach((pc) => pc.close())")
    stopped_unwatched(relay, vehicle, before, "bob")

    # Carl comes later: piloting is off, and his page says why. Bob's page, whose link closed,
    # connects again as the roster changes, and sees the same.
    carl = join(open_role, browser, "carl")
    wait_until(lambda: "bob" in status(relay)["watchers"], 60, "bob's link back")
    for client in (carl, bob):
        expect(client.get_by_test_id("state")).to_contain_text("not piloting")
        expect(client.get_by_test_id("stop-state")).to_contain_text("no client is watching")
    bob.close()
    wait_until(lambda: status(relay)["watchers"] == ["carl"], 30, "the relay seeing bob gone")

    # Carl's page crashes while piloting.
    start_piloting(carl, relay)
    before = stops_heard(vehicle)
    crash(browser, carl, "name=carl")
    stopped_unwatched(relay, vehicle, before, "carl")
    carl.close()

    # Dave's page closes while piloting.
    dave = join(open_role, browser, "dave")
    start_piloting(dave, relay)
    before = stops_heard(vehicle)
    dave.close()
    stopped_unwatched(relay, vehicle, before, "dave")
