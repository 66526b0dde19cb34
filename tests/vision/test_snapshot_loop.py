"""The relay's snapshot → goal loop (snapshot-loop.js) driven with frames, with no WebRTC.

Headless Chromium on the parity page, which has the relay's analyzer; the test imports the loop
module there, feeds it synthetic RGBA frames (faces pasted at known places, a frame tag in the
top row, or nothing at all) on an injected clock, and checks the goals it hands the sender and
what the target lock, held in the analyzer's worker, becomes.
"""

from __future__ import annotations

import base64
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from playwright.sync_api import Page

from app.protocol import channels, frametag
from app.protocol.channels import AUTOPILOT_CHANNEL, CONTROL_CHANNEL
from app.protocol.relay_profiles import DEFAULT_PROFILE
from app.resources import OPERATIONS_SPEC
from app.vision import lock, spec
from tests.helpers.harness import analyzer_page
from tests.vision.frames import Placed, face_crop
from tests.vision.relay_steps import RelaySteps
from vehicle_agent.video import TwoFaceVideo

pytestmark = [pytest.mark.browser, pytest.mark.slow]

WIDTH, HEIGHT = 640, 480
FACE_SIZE = 200
FRAME_STEP_MS = 50  # the injected clock advances this much per frame

# Feeds the frames in order (a null entry stops the loop), then three at once: the first is
# analysed, the second waits and is skipped when the third comes, the third waits and is analysed
# next. Returns what the loop emitted and resolved to.
DRIVE = """async ({ frames, profile, stepMs }) => {
  const { SnapshotLoop } = await import('/static/js/core/snapshot-loop.js');
  await window.analyzer.unlock(); // another test's lock
  const rgba = (b64) => ({ width: %d, height: %d,
    data: Uint8ClampedArray.from(atob(b64), (c) => c.charCodeAt(0)) });
  let now = 0;
  const sent = [];
  const emitted = { goal: [], detections: [] };
  const loop = new SnapshotLoop({
    analyzer: window.analyzer, profile, op: window.analyzer.defaultOp,
    sendGoal: (goal) => { sent.push(goal); return true; },
    clock: () => now, wallClock: () => 1.7e12 + now,
  });
  for (const type of Object.keys(emitted)) {
    loop.addEventListener(type, (event) => emitted[type].push(event.detail));
  }
  const beforeStart = await loop.frame(rgba(frames[0]));
  loop.start();
  const outcomes = [];
  for (const frame of frames) {
    now += stepMs;
    outcomes.push(await loop.frame(rgba(frame)));
  }
  const together = await Promise.all([0, 1, 2].map(() => loop.frame(rgba(frames[0]))));
  loop.stop();
  const afterStop = await loop.frame(rgba(frames[0]));
  return { beforeStart, outcomes, together, afterStop, sent, emitted,
           snapshots: loop.stats.snapshots, goalsSent: loop.stats.goalsSent };
}""" % (WIDTH, HEIGHT)  # noqa: UP031 -- the JS template has braces of its own


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with analyzer_page() as opened:
        yield opened


def faces(at: list[tuple[int, int, int]], tag: int, who: dict[int, str] | None = None) -> str:
    """Base64 RGBA of a grey frame with a face of side ``size`` at each ``(x, y, size)`` (its
    top-left corner) and a frame tag; ``who``: whose photo the face at an index is (Obama's
    unless said)."""
    frame = np.full((HEIGHT, WIDTH, 3), 128, np.uint8)
    for i, (x, y, size) in enumerate(at):
        photo = face_crop((who or {}).get(i, "obama.jpg"))
        frame[y : y + size, x : x + size] = cv2.resize(
            photo, (size, size), interpolation=cv2.INTER_AREA
        )
    frametag.stamp(frame, tag)
    rgba = cv2.cvtColor(frame, cv2.COLOR_BGR2RGBA)
    return base64.b64encode(rgba.tobytes()).decode()


def scene(face_at: tuple[int, int] | None, tag: int) -> tuple[str, Placed | None]:
    """Base64 RGBA of a grey frame with the face (top-left corner ``face_at``) and a tag."""
    if face_at is None:
        return faces([], tag), None
    x, y = face_at
    return faces([(x, y, FACE_SIZE)], tag), Placed(x, y, FACE_SIZE, FACE_SIZE)


def test_goals_follow_the_face_in_order_and_nothing_comes_without_one(page: Page) -> None:
    layout = [(40, 100), (400, 60), None, (220, 250), None]
    frames = [scene(at, tag=1000 + i) for i, at in enumerate(layout)]
    got: dict[str, Any] = page.evaluate(
        DRIVE,
        {"frames": [b64 for b64, _ in frames], "profile": DEFAULT_PROFILE, "stepMs": FRAME_STEP_MS},
    )
    assert got["beforeStart"] is None  # not piloting: no snapshot

    goals = []
    for i, ((_, placed), outcome) in enumerate(zip(frames, got["outcomes"], strict=True)):
        assert outcome is not None, f"frame {i} was not analysed"
        detections = outcome["detections"]
        assert isinstance(
            channels.validate(detections, CONTROL_CHANNEL, "client"), channels.Detections
        )
        if placed is None:
            assert outcome["goal"] is None and detections["target"] is None, (i, outcome)
            continue
        goal = outcome["goal"]
        checked = channels.validate(goal, AUTOPILOT_CHANNEL, "vehicle")
        assert isinstance(checked, channels.Goal), checked
        cx, cy = placed.centre
        assert abs(goal["x"] - cx) < FACE_SIZE / 4 and abs(goal["y"] - cy) < FACE_SIZE / 4, goal
        assert (goal["w"], goal["h"]) == (WIDTH, HEIGHT)
        assert goal["frame"] == 1000 + i  # the frame tag read back
        # The face's box (the cascade's, a little inside the pasted photo) and the real height
        # the face operation declares for it: a robot's camera reads the range from the two.
        assert FACE_SIZE * 0.5 < goal["boxH"] <= FACE_SIZE and goal["targetHeightM"] == 0.24
        assert goal["boxW"] == pytest.approx(goal["boxH"], rel=0.2), goal
        assert goal["t"] == 1.7e12 + (i + 1) * FRAME_STEP_MS
        goals.append(goal)

    assert [g["seq"] for g in goals] == [1, 2, 3]
    # What the sender got is what the loop announced, in the same order.
    assert got["sent"][:3] == goals == got["emitted"]["goal"][:3]
    assert len(got["emitted"]["detections"]) >= len(layout)
    # Goals per second over the 2 s window of the injected clock: three goals in 250 ms.
    assert got["outcomes"][-1]["detections"]["goalsPerS"] == pytest.approx(3 / 2)

    first, second, third = got["together"]
    assert first is not None and first["goal"]["seq"] == 4
    # One snapshot in flight at a time; the freshest frame offered meanwhile is analysed next,
    # and an older one waiting is skipped.
    assert second is None
    assert third is not None and third["goal"]["seq"] == 5
    assert got["sent"] == got["emitted"]["goal"] == [*goals, first["goal"], third["goal"]]
    assert got["afterStop"] is None
    assert (got["snapshots"], got["goalsSent"]) == (len(layout) + 2, 5)


# Steps [kind, t, arg] on the relay's loop (tracking on, as the relay runs it) with the clock at
# t seconds: "frame" analyses frames[arg], "click" locks at the frame point arg, "search" is the
# vehicle's pose saying how its search stands (arg: 'left', 'timed_out', null). Returns, for
# each, the goal's [x, y] (or null) and the lock's state, or whether the click locked; the lock
# messages the loop announced (the lock is the analyzer's worker's: another test's goes first);
# the details of each step: a snapshot's boxes, candidates and locked box, or the state, box
# and reason of the lock message a click led to; and the goals' box heights.
LOCK_STEPS = """async ({ frames, steps, profile }) => {
  const { SnapshotLoop } = await import('/static/js/core/snapshot-loop.js');
  const pixels = frames.map((b64) => new Uint8ClampedArray(fromBase64(b64).buffer));
  await window.analyzer.unlock();
  await window.analyzer.resetTracking();
  let now = 0;
  const loop = new SnapshotLoop({
    analyzer: window.analyzer, profile, op: window.analyzer.defaultOp, track: true,
    sendGoal: () => true, clock: () => now,
  });
  const messages = [];
  loop.addEventListener('lock', (event) => messages.push(event.detail));
  loop.start();
  const outcomes = [];
  const boxHeights = [];
  const details = [];
  for (const [kind, t, arg] of steps) {
    now = t * 1000;
    if (kind === 'search') {
      loop.vehicleSearch(arg);
      outcomes.push(null);
      boxHeights.push(null);
      details.push(null);
      continue;
    }
    if (kind === 'click') {
      outcomes.push(await loop.lockAt(arg[0], arg[1]));
      boxHeights.push(null);
      const { state, box, reason } = messages.at(-1);
      details.push({ state, box, reason });
      continue;
    }
    const outcome = await loop.frame({ width: %d, height: %d, data: pixels[arg] });
    outcomes.push([outcome.goal && [outcome.goal.x, outcome.goal.y], loop.lock.state]);
    boxHeights.push(outcome.goal && outcome.goal.boxH);
    const { boxes, candidates, locked } = outcome.detections;
    details.push([boxes, candidates, locked]);
  }
  loop.stop();
  await window.analyzer.unlock();
  return { outcomes, details, boxHeights, announced: messages.map((m) => m.state), messages };
}""" % (WIDTH, HEIGHT)  # noqa: UP031 -- the JS template has braces of its own


# An analyzer whose snapshots the test finishes by hand: the loop is stopped while one is being
# analysed, then it comes back with a target. A snapshot finished while running is the control.
STOP_IN_FLIGHT = """async () => {
  const { SnapshotLoop } = await import('/static/js/core/snapshot-loop.js');
  let finish = null;
  const analyzer = {
    analyze: () => new Promise((resolve) => { finish = resolve; }),
    lockAt: async () => ({ locked: false, state: 'none', box: null, reason: null }),
    unlock: async () => ({ released: false }),
  };
  const found = { op: 'face', target: { x: 320, y: 240 }, targetBox: null, frame: 7, w: 640,
    h: 480, boxes: [[300, 220, 40, 40]], candidates: [], ms: 1, workMs: 1,
    lock: { state: 'none', box: null, changed: null, reason: null } };
  const sent = [];
  const emitted = { goal: [], detections: [] };
  const loop = new SnapshotLoop({ analyzer, profile: 'default', op: 'face',
    sendGoal: (goal) => { sent.push(goal); return true; } });
  for (const type of Object.keys(emitted)) {
    loop.addEventListener(type, (event) => emitted[type].push(event.detail));
  }
  const frame = () => ({ width: 1, height: 1, data: new Uint8ClampedArray(4) });
  loop.start();
  let pending = loop.frame(frame());
  finish(found);
  const running = await pending;
  finish = null;
  pending = loop.frame(frame());
  const inFlight = finish !== null; // the analyzer has it
  loop.stop();
  finish(found);
  const stopped = await pending;
  return { running: running && running.goal.seq, inFlight, stopped, goals: sent.length,
           emitted: [emitted.goal.length, emitted.detections.length] };
}"""


def test_a_snapshot_in_flight_when_the_loop_stops_sends_no_goal(page: Page) -> None:
    got = page.evaluate(STOP_IN_FLIGHT)
    # The control: the same answer while running is goal 1, sent and told.
    assert got["running"] == 1
    # Stopped mid-analysis: the answer comes back with a target and is dropped whole.
    assert got["inFlight"] is True and got["stopped"] is None
    assert got["goals"] == 1 and got["emitted"] == [1, 1]


def test_a_locked_face_that_jumped_is_followed_by_its_look(page: Page) -> None:
    # The face is clicked, then shows up far from where it was (beyond the lock's reach: a
    # person who walked behind something and out the other side, or a camera that turned). Its
    # look, taken on the first snapshot after the click, tells it wherever it is in the frame:
    # it is the locked target at once, with no wait for the whole-frame search (1 s).
    (here, placed_here), (there, placed_there) = scene((40, 100), 1), scene((400, 220), 2)
    assert placed_here is not None and placed_there is not None
    steps = [
        ["frame", 0.05, 0],
        ["click", 0.06, list(placed_here.centre)],
        ["frame", 0.1, 0],
        ["frame", 0.6, 1],
        ["frame", 1.2, 1],
        ["frame", 1.25, 1],
    ]
    got: dict[str, Any] = page.evaluate(
        LOCK_STEPS, {"frames": [here, there], "steps": steps, "profile": DEFAULT_PROFILE}
    )
    outcomes = got["outcomes"]

    def on(goal: list[float] | None, placed: Placed) -> bool:
        cx, cy = placed.centre
        return (
            goal is not None
            and abs(goal[0] - cx) < FACE_SIZE / 4
            and abs(goal[1] - cy) < FACE_SIZE / 4
        )

    assert on(outcomes[0][0], placed_here) and outcomes[1] is True
    assert on(outcomes[2][0], placed_here) and outcomes[2][1] == "locked"
    assert on(outcomes[3][0], placed_there) and outcomes[3][1] == "locked"
    assert on(outcomes[4][0], placed_there) and outcomes[4][1] == "locked"
    assert on(outcomes[5][0], placed_there) and outcomes[5][1] == "locked"
    assert got["announced"] == ["locked"]


def test_a_click_locks_the_smaller_face_until_it_is_gone_past_the_release_time(page: Page) -> None:
    # Two faces: the larger is the target until the smaller one is clicked. The smaller face
    # then leaves (lost, and searched for in the whole frame after 1 s), comes back elsewhere
    # (found again), and leaves for longer than the release time (3 s): the lock lets go and
    # the larger face is the target again. The lock is decided in the analyzer's worker.
    large, small, small_elsewhere = (40, 100, 200), (420, 200, 130), (420, 10, 130)
    frames = [faces([large, small], 1), faces([large, small_elsewhere], 2), faces([large], 3)]
    small_centre = [small[0] + small[2] / 2, small[1] + small[2] / 2]
    steps = [
        ["frame", 0.05, 0],
        ["click", 0.07, small_centre],
        ["frame", 0.1, 0],
        ["frame", 0.15, 2],  # gone: lost
        ["frame", 1.2, 2],  # unseen for over 1 s: searching the whole frame
        ["frame", 1.25, 1],  # back, out of the lock's reach: found by the whole-frame search
        ["frame", 4.3, 2],  # unseen for over 3 s: released (this snapshot still looked)
        ["frame", 4.35, 2],
    ]
    got: dict[str, Any] = page.evaluate(
        LOCK_STEPS, {"frames": frames, "steps": steps, "profile": DEFAULT_PROFILE}
    )
    outcomes = got["outcomes"]

    def on(goal: list[float] | None, face: tuple[int, int, int]) -> bool:
        x, y, size = face
        return goal is not None and x < goal[0] < x + size and y < goal[1] < y + size

    assert on(outcomes[0][0], large) and outcomes[0][1] == "none"
    assert outcomes[1] is True
    assert on(outcomes[2][0], small) and outcomes[2][1] == "locked"
    # The goal's box is the locked face's, not the largest's: the range is the target's.
    heights = got["boxHeights"]
    assert 100 < heights[0] <= 200 and 65 < heights[2] <= 130, heights
    assert heights[2] < heights[0] * 0.75, heights
    assert outcomes[3] == [None, "lost"]
    assert outcomes[4] == [None, "searching"]
    assert on(outcomes[5][0], small_elsewhere) and outcomes[5][1] == "locked"
    assert outcomes[6] == [None, "none"]
    assert on(outcomes[7][0], large)
    assert got["announced"] == ["locked", "lost", "searching", "locked", "none"]
    assert "not seen for more than 3 s" in got["messages"][-1]["reason"]


def relay_snapshots_in_python(
    frames: list[npt.NDArray[np.uint8]], steps: list[list[Any]]
) -> list[Any]:
    """What LOCK_STEPS tells of each step (``combined``), from the Python reference and
    app/vision's lock and window as the relay's worker composes them (tests/vision/relay_steps.py):
    the same decisions on the same pixels."""
    op = spec.load_spec(OPERATIONS_SPEC).op("face")
    assert isinstance(op, spec.CascadeOperation)
    relay = RelaySteps(op)
    outcomes: list[Any] = []
    for kind, t, arg in steps:
        if kind == "click":
            relay.click(arg[0], arg[1], t)
            box = relay.lock.box
            outcomes.append({"state": relay.lock.state, "box": None if box is None else list(box)})
            continue
        snap = relay.snapshot(frames[arg], t)
        locked = relay.lock.box if relay.lock.state == "locked" else None
        outcomes.append(
            [
                None if snap.target is None else list(snap.target),
                relay.lock.state,
                [list(b) for b in snap.found.boxes],
                [list(b) for b in snap.candidates],
                None if locked is None else list(locked),
            ]
        )
    return outcomes


def combined(steps: list[list[Any]], answer: dict[str, Any]) -> list[Any]:
    """LOCK_STEPS' answer, step by step: a snapshot's [goal, state, boxes, candidates, locked],
    a click's {state, box}."""
    return [
        {"state": d["state"], "box": d["box"]} if kind == "click" else [*o, *d]
        for (kind, _, _), o, d in zip(steps, answer["outcomes"], answer["details"], strict=True)
    ]


def test_candidates_a_click_near_a_face_and_one_on_a_face_the_scan_misses_as_python_does(
    page: Page,
) -> None:
    # The two-face scene with its tiny face, as the relay's loop sees it: between full scans the
    # second face rides along as a candidate; a click near (not in) it locks it; a click on the
    # tiny face, which no scan of the reduced frame finds, locks it by the full-resolution search
    # around the click, and the goals follow it through the tracker's periodic full scan. Each
    # step as the Python reference, lock and window take it on the same pixels.
    scene = TwoFaceVideo(WIDTH, HEIGHT)
    indices = [0, 4, 8, 12]
    rgbas = [cv2.cvtColor(scene.render(i), cv2.COLOR_RGB2RGBA) for i in indices]
    frames = [base64.b64encode(rgba.tobytes()).decode() for rgba in rgbas]
    small_x, small_y = scene.small_centre(indices[1])
    tiny = scene.tiny_centre(indices[3])
    steps: list[list[Any]] = [["frame", 0.05 * (k + 1), k % 4] for k in range(4)]
    # Beside the small face's box: its centre plus 0.7 of its side to the right (beyond its
    # half-width box edge, within half its size past that edge).
    steps.append(["click", 0.21, [small_x + 0.7 * scene.small_px, small_y]])
    steps += [["frame", 0.25, 0], ["frame", 0.3, 1]]
    steps.append(["frame", 0.35, 3])  # a window snapshot, so the click finds no box near
    steps.append(["click", 0.36, list(tiny)])
    steps += [["frame", 0.4 + 0.05 * k, (3 - k % 2)] for k in range(33)]
    answer = page.evaluate(
        LOCK_STEPS, {"frames": frames, "steps": steps, "profile": DEFAULT_PROFILE}
    )
    got = combined(steps, answer)
    want = relay_snapshots_in_python(rgbas, steps)
    assert got == want

    def on(box: list[int] | None, centre: tuple[float, float]) -> bool:
        return box is not None and lock.contains((box[0], box[1], box[2], box[3]), *centre)

    first, windowed = got[0], got[1]
    assert len(first[2]) == 2  # the full scan found both faces
    assert len(windowed[2]) == 1 and len(windowed[3]) == 2  # the window: one, and two candidates
    near = got[4]
    assert near["state"] == "locked" and on(near["box"], (small_x, small_y))
    assert not lock.contains(tuple(near["box"]), *steps[4][2])  # type: ignore[arg-type]
    search = got[8]
    assert search["state"] == "locked" and on(search["box"], tiny)
    reasons = [
        d["reason"]
        for (kind, _, _), d in zip(steps, answer["details"], strict=True)
        if kind == "click"
    ]
    assert reasons == [None, "found by a full-resolution search around the click"]
    followed = got[9:]
    assert all(
        o[1] == "locked" and on(o[4], scene.tiny_centre(indices[3 - k % 2]))
        for k, o in enumerate(followed)
    )


def test_the_lock_holds_while_the_vehicle_searches_and_lets_go_when_the_search_ends(
    page: Page,
) -> None:
    # Two people: the smaller face (Obama's) is clicked and leaves; the vehicle's poses say it
    # turns to search for it. Past the release time (3 s unseen) the lock still holds, and the
    # face coming back much nearer (more than max_scale, 1.4 times the size: its size and place
    # no longer tell it) is recognised by its look and is the target again with no click, while
    # the other person's face (Biden's) never is. It leaves again, the vehicle's search runs out
    # (timed_out): the lock lets go, and the larger face is the target.
    large, small, small_back = (40, 100, 200), (420, 200, 130), (380, 150, 220)
    biden = {0: "biden.jpg"}
    frames = [
        faces([large, small], 1, biden),
        faces([large, small_back], 2, biden),
        faces([large], 3, biden),
    ]
    small_centre = [small[0] + small[2] / 2, small[1] + small[2] / 2]
    steps = [
        ["frame", 0.05, 0],
        ["click", 0.07, small_centre],
        ["frame", 0.1, 0],
        ["frame", 0.15, 2],  # gone: lost
        ["search", 0.5, "left"],
        ["frame", 4.3, 2],  # unseen for over 3 s: held, the vehicle searches
        ["frame", 4.35, 1],  # back: the target again, no click
        ["search", 4.4, None],
        ["frame", 4.45, 2],
        ["search", 4.8, "right"],
        ["search", 7.9, "timed_out"],
        ["frame", 7.95, 2],  # unseen since 4.35 and the search is over: released
        ["frame", 8.0, 2],
    ]
    got: dict[str, Any] = page.evaluate(
        LOCK_STEPS, {"frames": frames, "steps": steps, "profile": DEFAULT_PROFILE}
    )
    outcomes = got["outcomes"]

    def on(goal: list[float] | None, face: tuple[int, int, int]) -> bool:
        x, y, size = face
        return goal is not None and x < goal[0] < x + size and y < goal[1] < y + size

    assert on(outcomes[2][0], small) and outcomes[2][1] == "locked"
    assert outcomes[3] == [None, "lost"]
    assert outcomes[5] == [None, "searching"]
    assert on(outcomes[6][0], small_back) and outcomes[6][1] == "locked"
    assert outcomes[8] == [None, "lost"]
    assert outcomes[11] == [None, "none"]
    assert on(outcomes[12][0], large)
    assert got["announced"] == ["locked", "lost", "searching", "locked", "lost", "none"]
    assert "the robot is not searching" in got["messages"][-1]["reason"]
