"""The browser vehicle's control law (control.js) agrees with the Python agent's (control.py)."""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from vehicle_agent import control

pytestmark = [pytest.mark.browser]

W, H = 640, 480
GOAL_PIXELS = [(x, y) for x in (0, 100, 319, 320, 321, 500, 639) for y in (0, 120, 240, 400, 479)]
POSES = [
    (5.544445, 5.544445, theta)
    for theta in (-math.pi, -2.0, -math.pi / 2, 0.0, 0.5, math.pi / 2, 3.0, math.pi)
] + [(1.0, 9.0, 0.3), (10.5, 0.5, -2.9)]


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    opened = browser.new_page()
    opened.goto(server.url + "/")
    opened.evaluate("async () => { window.control = await import('/static/js/control.js'); }")
    yield opened
    opened.close()


def test_steering_and_commands_match_the_python_agent(page: Page) -> None:
    cases: list[dict[str, dict[str, float]]] = [
        {"goal": {"x": x, "y": y, "w": W, "h": H}, "pose": {"x": px, "y": py, "theta": th}}
        for (x, y), (px, py, th) in itertools.product(GOAL_PIXELS, POSES)
    ]
    js: list[dict[str, Any]] = page.evaluate(
        """cases => cases.map(({ goal, pose }) => {
             const e = control.steeringError(goal, pose);
             return {
               terrain: control.pixelToTerrain(goal.x, goal.y, goal.w, goal.h),
               error: e,
               default: e === null ? null : control.angularCommand(e, control.PROFILES.default),
               thesis: e === null ? null : control.angularCommand(e, control.PROFILES.thesis),
             };
           })""",
        cases,
    )
    for case, got in zip(cases, js, strict=True):
        g, p = case["goal"], case["pose"]
        goal = control.Goal(g["x"], g["y"], int(g["w"]), int(g["h"]))
        pose = control.Pose(p["x"], p["y"], p["theta"])
        tx, ty = control.pixel_to_terrain(goal.x, goal.y, goal.w, goal.h)
        assert got["terrain"]["x"] == pytest.approx(tx) and got["terrain"]["y"] == pytest.approx(ty)
        error = control.steering_error(goal, pose)
        if error is None:
            assert got["error"] is None, case
            continue
        assert got["error"] == pytest.approx(error, abs=1e-12), case
        for name in ("default", "thesis"):
            expected = control.angular_command(error, control.PROFILES[name])
            assert got[name] == pytest.approx(expected, abs=1e-12), (case, name)


def test_wrap_angle_matches_including_the_boundaries(page: Page) -> None:
    angles = [k * math.pi / 4 for k in range(-12, 13)] + [-math.pi, math.pi, 7.0, -7.0, 1e-9]
    js = page.evaluate("angles => angles.map((a) => control.wrapAngle(a))", angles)
    for angle, got in zip(angles, js, strict=True):
        assert -math.pi < got <= math.pi
        assert got == pytest.approx(control.wrap_angle(angle), abs=1e-12), angle


def test_a_face_on_the_left_turns_the_turtle_counter_clockwise(page: Page) -> None:
    # The turtle faces up (θ = π/2) at the centre; a face left of centre, level with it, is
    # straight to its left: a quarter turn counter-clockwise (positive).
    error = page.evaluate(
        "() => control.steeringError({x: 100, y: 240, w: 640, h: 480},"
        " {x: 5.544445, y: 5.544445, theta: Math.PI / 2})"
    )
    assert error == pytest.approx(math.pi / 2, abs=1e-6)


@pytest.mark.parametrize("profile", ["default", "thesis"])
def test_controller_timeline_matches_the_python_agent(page: Page, profile: str) -> None:
    # One scripted session on a fake clock (ms): goals, poses, ticks, a timeout and a stop.
    # The 37 ms grid never lands exactly on a 50 or 1100 ms period boundary, where ms (JS) and
    # s (Python) floating point could round either way.
    events: list[tuple[str, float, dict[str, float] | None]] = []
    goal = {"x": 100.0, "y": 240.0, "w": W, "h": H}
    t = 0.0
    for step in range(130):
        t = step * 37.0
        if step < 65 and step % 3 == 0:
            events.append(("goal", t, goal))
        events.append(("pose", t + 5.3, {"x": 5.544445, "y": 5.544445, "theta": 0.02 * step}))
        events.append(("tick", t + 10.7, None))
    events.append(("goal", t + 100, goal))
    events.append(("stop", t + 150, None))
    events.append(("stop", t + 200, None))

    js = page.evaluate(
        """([profile, events]) => {
             let now = 0;
             const c = new control.Controller(control.PROFILES[profile], () => now);
             return events.map(([kind, t, arg]) => {
               now = t;
               const twist = kind === 'goal' ? c.goal(arg) : kind === 'pose' ? c.pose(arg)
                 : kind === 'tick' ? c.tick() : c.stop();
               return twist === null ? null : twist.angular;
             });
           }""",
        [profile, events],
    )
    now = 0.0
    controller = control.Controller(control.PROFILES[profile], clock=lambda: now)
    expected: list[float | None] = []
    for kind, t_ms, arg in events:
        now = t_ms / 1000
        if kind == "goal":
            assert arg is not None
            twist = controller.goal(control.Goal(arg["x"], arg["y"], int(arg["w"]), int(arg["h"])))
        elif kind == "pose":
            assert arg is not None
            twist = controller.pose(control.Pose(**arg))
        elif kind == "tick":
            twist = controller.tick()
        else:
            twist = controller.stop()
        expected.append(None if twist is None else twist.angular_z)
    assert any(v is not None and v != 0 for v in expected), "the script never drove the turtle"
    assert expected.count(0.0) >= 1, "the script never stopped the turtle"
    assert js == pytest.approx(expected, abs=1e-12)
