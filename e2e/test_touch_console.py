"""The client's console on the screens an operator holds: a phone (390×844), a tablet (1024×768)
and a desktop (1280×800), each a touch screen, watching one room (a browser vehicle, the relay
page). On each: the page at the screen's own width with nothing to scroll sideways; the video,
its boxes and the piloting and driving buttons on screen together (the turtle view too from a
tablet's width), the video the largest; the live figures one line each; a screenshot of each
screen kept in artifacts/. Then from each screen in turn: Take Over, and the joystick turns the
turtle the way it is dragged (a second finger on the pad changes nothing); letting go -- lifting
the finger, or the browser cancelling the touch -- stops it within 0.35 s, by the client's zero
command and not the vehicle's dead-man.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser, FloatRect, Locator, Page, expect

from app.server.serve import RunningServer
from e2e.conftest import OpenRole, artifacts_dir
from e2e.helpers import Touches, ccw_from, theta, wait_for_live_video, wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]
# How far two browsers' clocks on one machine may disagree: a few milliseconds, with margin.
CLOCKS_APART_MS = 50

ROOM = "touch"
SCREENS: dict[str, dict[str, Any]] = {
    "phone": {"viewport": {"width": 390, "height": 844}, "is_mobile": True, "has_touch": True},
    "tablet": {"viewport": {"width": 1024, "height": 768}, "is_mobile": True, "has_touch": True},
    "desktop": {"viewport": {"width": 1280, "height": 800}, "has_touch": True},
}
# How the joystick is dragged on each screen (+1 left: counter-clockwise; −1 right) and let go.
DRIVES = (("phone", +1, "lift"), ("tablet", -1, "cancel"), ("desktop", +1, "lift"))

# On the vehicle page: each Twist it publishes, on the machine's clock (ms), which every page of
# the browser shares, and whether it answers a drive command (the operator's) or not (the
# dead-man's stop, say): the page counts a drive command applied just before publishing its
# Twist.
WATCH_THE_VEHICLE = """() => {
  const status = window.autopilotStatus;
  window.twists = [];
  let drives = status.drivesApplied;
  let twist = status.lastTwist;
  let driven = false;
  Object.defineProperty(status, 'drivesApplied', {
    get: () => drives,
    set: (value) => {
      drives = value;
      driven = true;
    },
  });
  Object.defineProperty(status, 'lastTwist', {
    get: () => twist,
    set: (value) => {
      twist = value;
      const at = performance.timeOrigin + performance.now();
      twists.push({ at, zero: value.linear === 0 && value.angular === 0, driven });
      driven = false;
    },
  });
}"""
# On a client page: when fingers left the joystick (lifted or cancelled), on the same clock.
WATCH_THE_PAD = """(pad) => {
  window.padLifts = [];
  for (const type of ['pointerup', 'pointercancel']) {
    pad.addEventListener(type, () => padLifts.push(performance.timeOrigin + performance.now()));
  }
}"""
# Each live figure's name and value, and how many lines its text takes.
FIGURE_LINES = """() => [...document.querySelectorAll('.figures dt, .figures dd')].map((el) => {
  const range = document.createRange();
  range.selectNodeContents(el);
  const tops = new Set([...range.getClientRects()].map((rect) => Math.round(rect.top)));
  return [el.textContent, tops.size];
})"""
# The area of the video's picture (letterboxed in its element) and of the turtle's square view.
AREAS = """() => {
  const video = document.querySelector('[data-testid=video]');
  const box = video.getBoundingClientRect();
  const scale = Math.min(box.width / video.videoWidth, box.height / video.videoHeight);
  const turtle = document.querySelector('[data-testid=turtle-view]').getBoundingClientRect();
  const side = Math.min(turtle.width, turtle.height);
  return [video.videoWidth * video.videoHeight * scale ** 2, side ** 2];
}"""


def on_screen(page: Page, target: Locator) -> bool:
    """Whether ``target`` is wholly inside the window, as the page is scrolled now."""
    box: FloatRect | None = target.bounding_box()
    size = page.viewport_size
    assert box is not None and size is not None
    return (
        box["x"] >= 0
        and box["y"] >= 0
        and box["x"] + box["width"] <= size["width"]
        and box["y"] + box["height"] <= size["height"]
    )


def check_layout(name: str, page: Page) -> None:
    width = SCREENS[name]["viewport"]["width"]
    page.evaluate("() => scrollTo(0, 0)")
    # At the screen's own width (a wider page would be zoomed out to fit), nothing sideways.
    assert page.evaluate("innerWidth") == width, name
    assert page.evaluate("document.scrollingElement.scrollWidth") <= width, name
    # The video with its boxes, and the buttons that pilot and drive, all on the first screen.
    shown = [page.get_by_test_id("video"), page.get_by_test_id("overlay")]
    shown += [
        page.get_by_role("button", name=label)
        for label in ("Start Piloting", "Stop Piloting", "Take Over", "Hand Back")
    ]
    if name != "phone":  # a phone shows the turtle below
        shown.append(page.get_by_test_id("turtle-view"))
    for target in shown:
        assert on_screen(page, target), f"{name}: {target} is not on screen"
    picture, turtle = page.evaluate(AREAS)
    assert picture > turtle, f"{name}: the video ({picture} px²) is smaller than the turtle view"
    # The thesis's controls are all there, below on a phone.
    for label in ("Connect", "Join Room", "Leave Room", "Set Operation"):
        expect(page.get_by_role("button", name=label)).to_be_visible()
    expect(page.get_by_label("Select Operation")).to_be_visible()
    # The figures legible: each name and each value on one line.
    lines = page.evaluate(FIGURE_LINES)
    assert lines and all(count == 1 for _, count in lines), f"{name}: {lines}"


def screenshot(client: Page, folder: Path, name: str, suffix: str = "") -> None:
    """The window as the operator sees it, kept as ``console-<screen>-<W>x<H><suffix>.png``."""
    size = SCREENS[name]["viewport"]
    client.screenshot(
        path=str(folder / f"console-{name}-{size['width']}x{size['height']}{suffix}.png")
    )


def drive(
    server: RunningServer,
    vehicle: Page,
    client: Page,
    name: str,
    turn: int,
    letting_go: str,
    folder: Path,
) -> None:
    """Take Over on ``client``, drag the joystick to turn (+1 left, −1 right), a second finger
    on the pad meanwhile, let go (``lift`` or ``cancel``); then Hand Back."""
    client.evaluate("() => scrollTo(0, 0)")
    client.get_by_role("button", name="Take Over").click()
    expect(client.get_by_test_id("mode")).to_contain_text("you drive")
    pad = client.get_by_label("Drive joystick")
    expect(pad).to_have_attribute("aria-disabled", "false")
    assert on_screen(client, pad) and on_screen(client, client.get_by_test_id("video")), name
    box = pad.bounding_box()
    assert box is not None
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    reach = box["width"] / 2 - 12  # just inside the rim: full speed
    pad.evaluate(WATCH_THE_PAD)
    vehicle.evaluate("() => { twists.length = 0; }")

    touches = Touches(client)
    start = theta(server)
    touches.press(1, cx, cy)
    touches.move(1, cx - turn * reach, cy)
    wait_until(
        lambda: turn * ccw_from(start, theta(server)) > math.radians(45),
        20,
        f"{name}: the turtle turning the way the joystick is dragged",
    )
    assert client.evaluate("scrollY") == 0, f"{name}: dragging the joystick scrolled the page"
    screenshot(client, folder, name, "-driving")

    # A second finger presses, moves and lifts on the pad: the first still drives.
    touches.press(2, cx + turn * reach / 2, cy + reach / 2)
    touches.move(2, cx, cy - reach)
    touches.lift(2)
    mid = theta(server)
    wait_until(
        lambda: turn * ccw_from(mid, theta(server)) > math.radians(30),
        20,
        f"{name}: still turning after a second finger came and went",
    )
    if letting_go == "lift":
        touches.lift(1)
    else:
        touches.cancel()
    wait_until(
        lambda: vehicle.evaluate("() => twists.some((twist) => twist.zero && twist.driven)"),
        5,
        f"{name}: the operator's stop once let go",
    )
    lifted_at: float = client.evaluate("() => padLifts.at(-1)")
    twists: list[dict[str, Any]] = vehicle.evaluate("() => twists")
    stops = [twist["at"] for twist in twists if twist["zero"] and twist["driven"]]
    # The client sent no stop while the first finger held the pad (the second one came and
    # went); letting go sent one, and the vehicle stopped the turtle on it within 0.35 s (had
    # it been left to the dead-man, that stop would not answer a drive command).
    # The two times come from two browsers' clocks (performance.timeOrigin + now()), which can
    # disagree by a few milliseconds; a stop sent for the second finger would come hundreds of
    # milliseconds earlier (the turtle turned 30° after it).
    assert stops and stops[0] >= lifted_at - CLOCKS_APART_MS, (name, lifted_at, twists)
    assert stops[0] - lifted_at <= 350, (name, lifted_at, twists)
    held = theta(server)
    time.sleep(1.0)
    assert theta(server) == pytest.approx(held, abs=1e-9), f"{name}: moved after the release"

    client.get_by_role("button", name="Hand Back").click()
    expect(client.get_by_test_id("mode")).to_have_text("autopilot steers")


def test_the_console_on_a_phone_a_tablet_and_a_desktop(
    request: pytest.FixtureRequest,
    server: RunningServer,
    open_role: OpenRole,
    browser: Browser,
    vehicle_browser: Browser,
) -> None:
    query = {"room": ROOM, "auto": "1"}
    vehicle = open_role("vehicle", vehicle_browser, name="vehicle", **query)
    open_role("relay", browser, name="relay", **query)
    clients = {
        name: open_role("client", browser, device=device, name=name, **query)
        for name, device in SCREENS.items()
    }
    start = clients["desktop"].get_by_role("button", name="Start Piloting")
    expect(start).to_be_enabled(timeout=120_000)
    start.click()
    folder = artifacts_dir(request)
    for name, client in clients.items():
        wait_for_live_video(client)
        client.wait_for_function("() => window.autopilotStatus.lastDetections?.boxes?.length > 0")
        check_layout(name, client)
        screenshot(client, folder, name)

    vehicle.evaluate(WATCH_THE_VEHICLE)
    for name, turn, letting_go in DRIVES:
        drive(server, vehicle, clients[name], name, turn, letting_go, folder)
