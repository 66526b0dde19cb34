"""The drive joystick of the client's console: its rule (core/joystick.js: where a finger holds
the pad → a drive command, on the keys' scale), one finger driving it whatever other fingers do,
the pad (view/joystick.js) under real touches from Chromium's input pipeline, and the drive
commands it makes (view/drive-input.js): at once, repeated while held, zero at once when let go.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from e2e.helpers import Touches, module_page

pytestmark = [pytest.mark.browser]

RADIUS = 50  # the knob's travel in the rule's cases, in pixels


@pytest.fixture
def joystick(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/joystick") as page:
        page.evaluate(
            "async () => { window.drive = await import('/static/js/view/drive-input.js'); }"
        )
        # A gesture, the public way in: one finger pressed at (dx, dy) from the pad's centre.
        page.evaluate(
            """() => {
              window.pressed = (dx, dy, radius) => {
                const gesture = new joystick.StickGesture();
                gesture.press(1, dx, dy, { x: 0, y: 0 }, radius);
                return gesture;
              };
            }"""
        )
        yield page


def commands(page: Page, offsets: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """(linear, angular) of a finger at each (dx, dy) from the centre (screen axes, y down)."""
    got: list[list[float]] = page.evaluate(
        """([offsets, radius]) => offsets.map(([dx, dy]) => {
             const c = pressed(dx, dy, radius).command;
             return [c.linear, c.angular];
           })""",
        [offsets, RADIUS],
    )
    return [(linear, angular) for linear, angular in got]


# The command the console sends while the arrow keys `held` are down (pressed in that order),
# from the page's own keyboard events.
KEYS_JS = """(held) => {
  const sent = [];
  const input = new drive.DriveInput({
    repeatS: 60,
    send: (c) => sent.push([c.linear, c.angular]),
    gamepads: () => [],
  });
  input.setEnabled(true);
  for (const key of held) dispatchEvent(new KeyboardEvent('keydown', { key }));
  const command = sent.at(-1);
  input.setEnabled(false); // and the keys let go
  return command;
}"""


def keys(page: Page, held: list[str]) -> tuple[float, float]:
    """(linear, angular) the console sends while the arrow keys ``held`` are down."""
    got: list[float] = page.evaluate(KEYS_JS, held)
    return got[0], got[1]


def test_up_drives_forward_left_turns_counter_clockwise_as_the_arrow_keys(joystick: Page) -> None:
    r = RADIUS
    rim = {"ArrowUp": (0, -r), "ArrowDown": (0, r), "ArrowLeft": (-r, 0), "ArrowRight": (r, 0)}
    for key, offset in rim.items():
        assert commands(joystick, [offset]) == [keys(joystick, [key])], key
    # The keys' limits: beyond the rim, and at a corner (two keys held), each axis stays at ±1.
    assert commands(joystick, [(-4 * r, -4 * r)]) == [keys(joystick, ["ArrowUp", "ArrowLeft"])]
    assert commands(joystick, [(0, -3 * r)]) == [keys(joystick, ["ArrowUp"])]
    assert keys(joystick, ["ArrowUp", "ArrowLeft"]) == (1, 1)


def test_the_offset_is_the_command_and_a_resting_finger_commands_nothing(joystick: Page) -> None:
    r = RADIUS
    # Halfway to the rim is half speed; a quarter back and three quarters right, likewise.
    assert commands(joystick, [(-r / 2, 0), (3 * r / 4, r / 4)]) == [(0, 0.5), (-0.25, -0.75)]
    # A finger resting near the centre (a pixel or two of wobble) does not drive.
    assert commands(joystick, [(0, 0), (2, -2), (-3, 1)]) == [(0, 0)] * 3
    # Every command on a grid far past the pad is within the keys' limits.
    grid = [(dx, dy) for dx in range(-200, 201, 10) for dy in range(-200, 201, 10)]
    assert all(-1 <= v <= 1 for command in commands(joystick, grid) for v in command)


def test_the_knob_follows_the_finger_within_the_rim(joystick: Page) -> None:
    got = joystick.evaluate(
        """(r) => [[10, -20], [0, -3 * r], [3 * r, 4 * r]].map(([dx, dy]) => {
             const k = pressed(dx, dy, r).knob;
             return [k.x, k.y];
           })""",
        RADIUS,
    )
    assert got[0] == [10, -20]  # inside the rim: under the finger
    assert got[1] == pytest.approx([0, -RADIUS])  # beyond it: on the rim, toward the finger
    assert got[2] == pytest.approx([0.6 * RADIUS, 0.8 * RADIUS])


# A gesture scripted as [method, pointer, x, y]; each step gives [changed, command or null].
GESTURE_JS = """([steps, radius]) => {
  const gesture = new joystick.StickGesture();
  const centre = { x: 100, y: 100 };
  return steps.map(([method, id, x, y]) => {
    const changed =
      method === 'press' ? gesture.press(id, x, y, centre, radius)
      : method === 'move' ? gesture.move(id, x, y)
      : method === 'lift' ? gesture.lift(id)
      : gesture.release();
    const c = gesture.command;
    return [changed, c === null ? null : [c.linear, c.angular]];
  });
}"""


def test_one_finger_drives_and_a_second_neither_moves_nor_releases_it(joystick: Page) -> None:
    r = RADIUS
    steps = [
        ["press", 7, 100 - r, 100],  # finger 7 on the pad's left edge: full left turn
        ["press", 9, 100, 100 - r],  # a second finger, on the top edge
        ["move", 9, 100 + r, 100],  # it moves
        ["lift", 9, 0, 0],  # and lifts
        ["move", 7, 100, 100 + r],  # the first finger moves to the bottom edge: full reverse
        ["lift", 7, 0, 0],  # and lifts: released
        ["move", 7, 100 - r, 100],  # a lifted finger's late move changes nothing
        ["press", 9, 100 + r, 100],  # once free, any finger may take it
        ["release", None, 0, 0],  # the page lets go (the wheel went to someone else)
    ]
    got = joystick.evaluate(GESTURE_JS, [steps, r])
    assert got == [
        [True, [0, 1]],
        [False, [0, 1]],
        [False, [0, 1]],
        [False, [0, 1]],
        [True, [-1, 0]],
        [True, None],
        [False, None],
        [True, [0, -1]],
        [True, None],
    ]


# The pad as the client page builds it (its markup, app.css), its commands kept in `got`.
PAD_JS = """async () => {
  document.body.style.minHeight = '3000px'; // a page that can scroll
  document.body.insertAdjacentHTML(
    'afterbegin',
    '<div class="joystick" aria-label="Drive joystick" hidden><div class="knob"></div></div>',
  );
  const { Joystick } = await import('/static/js/view/joystick.js');
  const element = document.querySelector('.joystick');
  window.got = [];
  window.presses = 0; // fingers pressed on the pad
  element.addEventListener('pointerdown', () => { presses += 1; });
  window.pad = new Joystick(element, (c) => {
    got.push(c === null ? null : [c.linear, c.angular]);
  });
  pad.show();
}"""


@pytest.fixture
def touch_page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    context = browser.new_context(
        viewport={"width": 390, "height": 844}, has_touch=True, is_mobile=True
    )
    page = context.new_page()
    page.goto(server.url + "/")
    page.evaluate(PAD_JS)
    try:
        yield page
    finally:
        context.close()


def got(page: Page) -> list[Any]:
    result: list[Any] = page.evaluate("() => got.splice(0)")
    return result


def test_the_pad_under_real_touches(touch_page: Page) -> None:
    page = touch_page
    touches = Touches(page)
    box = page.get_by_label("Drive joystick").bounding_box()
    assert box is not None
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2

    # Off (nobody holds the wheel here): a touch drives nothing.
    touches.press(1, cx - 40, cy)
    touches.lift(1)
    assert got(page) == []

    page.evaluate("() => pad.setEnabled(true)")
    # One finger drags to the left and on, up and far past the pad (its pointer is captured):
    # full left, then forward and full left.
    touches.press(1, cx, cy)
    touches.move(1, cx - box["width"], cy)
    touches.move(1, cx - box["width"], cy - box["height"])
    seen = got(page)
    assert seen[0] == [0, 0] and seen[-1] == [1, 1], seen
    assert any(command == [0, 1] for command in seen), seen
    # Dragging the pad never scrolls the page.
    assert page.evaluate("scrollY") == 0

    # A second finger on the pad: it moves and lifts, and the first still drives, unchanged
    # (Chromium reports the first finger's position again with each move of the second).
    touches.press(2, cx + 20, cy + 20)
    touches.move(2, cx + 60, cy + 60)
    touches.lift(2)
    assert all(command == [1, 1] for command in got(page))
    assert page.evaluate("presses") == 3  # the touch when off, the first finger, the second
    # The first lifts: released at once.
    touches.lift(1)
    assert got(page) == [None]

    # A cancelled touch is a lifted finger.
    edge = box["width"] / 2 - 10  # just inside the rim
    touches.press(3, cx, cy + edge)
    touches.cancel()
    assert got(page) == [[-1, 0], None]

    # Turned off while a finger holds it (the wheel went elsewhere): released, and that finger's
    # moves drive nothing any more.
    touches.press(4, cx + edge, cy)
    page.evaluate("() => pad.setEnabled(false)")
    touches.move(4, cx, cy - box["height"] / 2)
    touches.lift(4)
    assert got(page) == [[0, -1], None]

    # The same drag anywhere else on the page scrolls it (so the pad's stillness above is the
    # pad's doing).
    touches.press(5, 200, 700)
    touches.move(5, 200, 300, steps=10)
    touches.lift(5)
    page.wait_for_function("() => scrollY > 0")


# DriveInput with the joystick's commands, its `send` recorded with the page's clock (ms).
DRIVE_JS = """async ([repeatS]) => {
  const sent = [];
  const start = performance.now();
  const input = new drive.DriveInput({
    repeatS,
    send: (c) => sent.push([performance.now() - start, c.linear, c.angular]),
    gamepads: () => [],
  });
  const wait = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
  input.setStick({ linear: 0, angular: 1 }); // the wheel is not this client's: nothing
  input.setEnabled(true);
  input.setStick({ linear: 0, angular: 1 });
  await wait(500);
  const held = sent.length;
  const liftedAt = performance.now() - start;
  input.setStick(null);
  await wait(400);
  input.setEnabled(false);
  return { sent, held, liftedAt };
}"""


def test_the_joystick_drives_as_a_held_key_and_stops_the_moment_it_is_let_go(
    joystick: Page,
) -> None:
    run = joystick.evaluate(DRIVE_JS, [0.1])
    sent, lifted_at = run["sent"], run["liftedAt"]
    held = sent[: run["held"]]
    # At once on the finger's press, then again while held (every 0.1 s, for 0.5 s: at least
    # a few repeats on a loaded machine), so the vehicle's 0.3 s dead-man never fires.
    assert held[0][1:] == [0, 1] and held[0][0] < 50, sent
    assert len(held) >= 3 and all(entry[1:] == [0, 1] for entry in held), sent
    # Let go: one zero command, at once, and nothing after.
    assert sent[len(held) :] == [[pytest.approx(lifted_at, abs=1), 0, 0]], sent
