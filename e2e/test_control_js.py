"""The browser vehicle's control law (control.js) agrees with the Python agent's (control.py).

control.js gets its numbers the way the vehicle page does, from ``control_config()``, and is
compared with the Python law on a grid of goals and poses and on scripted sessions.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.protocol.control import control_config, for_robot
from app.protocol.page import to_json
from app.protocol.robot import PRESETS
from app.server.serve import RunningServer
from vehicle_agent.core import control

pytestmark = [pytest.mark.browser]

W, H = 640, 480
GOAL_PIXELS = [(x, y) for x in (0, 100, 319, 320, 321, 500, 639) for y in (0, 120, 240, 400, 479)]
POSES = [
    (5.544445, 5.544445, theta)
    for theta in (-math.pi, -2.0, -math.pi / 2, 0.0, 0.5, math.pi / 2, 3.0, math.pi)
] + [(1.0, 9.0, 0.3), (10.5, 0.5, -2.9), (0.3, 5.0, math.pi), (10.9, 10.9, 0.8), (6.0, 2.0, -1.2)]
PROFILE_NAMES = sorted(control.PROFILES)
# The profiles as the pages get them, the onboard one on the diffdrive robot (its 60° camera),
# and the follow profile as a robot other than a turtlesim gets it: no terrain walls to keep from.
ROVER_FOLLOW = for_robot(control.PROFILES["follow"], PRESETS["diffdrive"])
ONBOARD = for_robot(control.PROFILES["onboard"], PRESETS["diffdrive"])
PROFILES = {**control.PROFILES, "onboard": ONBOARD, "roverFollow": ROVER_FOLLOW}


def command(js: dict[str, float]) -> tuple[float, float, float]:
    """What control.js's law asks for: its speeds and the share of the top speed allowed."""
    return js["linear"], js["angular"], js["topShare"]


def wanted(twist: control.Twist) -> tuple[float, float, float]:
    """What control.py's law asks for, as :func:`command` reads control.js's."""
    return twist.linear_x, twist.angular_z, twist.top_share


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    opened = browser.new_page()
    opened.goto(server.url + "/")
    opened.evaluate(
        """async (constants) => {
             window.control = await import('/static/js/core/control.js');
             window.law = new control.ControlLaw(constants);
           }""",
        to_json(control_config(PROFILES)),
    )
    yield opened
    opened.close()


def test_steering_and_commands_match_the_python_agent(page: Page) -> None:
    cases: list[dict[str, dict[str, float]]] = [
        {"goal": {"x": x, "y": y, "w": W, "h": H}, "pose": {"x": px, "y": py, "theta": th}}
        for (x, y), (px, py, th) in itertools.product(GOAL_PIXELS, POSES)
    ]
    js: list[dict[str, Any]] = page.evaluate(
        """cases => cases.map(({ goal, pose }) => {
             const e = law.steeringError(goal, pose);
             return {
               terrain: law.pixelToTerrain(goal.x, goal.y, goal.w, goal.h),
               error: e,
               default: e === null ? null : law.angularCommand(e, law.profiles.default),
               thesis: e === null ? null : law.angularCommand(e, law.profiles.thesis),
               follow: law.follow(goal, pose, law.profiles.follow),
               roverFollow: law.follow(goal, pose, law.profiles.roverFollow),
               ahead: law.wallClearance(pose, true),
               behind: law.wallClearance(pose, false),
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
        for name, profile in (
            ("follow", control.PROFILES["follow"]),
            ("roverFollow", ROVER_FOLLOW),
        ):
            assert command(got[name]) == pytest.approx(
                wanted(control.follow_command(tx, ty, pose, profile)), abs=1e-12
            ), (case, name)
        assert got["ahead"] == pytest.approx(control.wall_clearance(pose, True), abs=1e-12)
        assert got["behind"] == pytest.approx(control.wall_clearance(pose, False), abs=1e-12)
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
    # Through the steering error, the public way in: a target straight along +x from a turtle
    # heading −a is a turn of a, wrapped.
    js = page.evaluate(
        """angles => angles.map((a) => law.steeringError(
             { x: 320, y: 240, w: 640, h: 480 },
             { x: law.terrainCentre - 1, y: law.terrainCentre, theta: -a },
           ))""",
        angles,
    )
    for angle, got in zip(angles, js, strict=True):
        assert -math.pi < got <= math.pi
        assert got == pytest.approx(control.wrap_angle(angle), abs=1e-12), angle


def test_a_face_on_the_left_turns_the_turtle_counter_clockwise(page: Page) -> None:
    # The turtle faces up (θ = π/2) at the centre; a face left of centre, level with it, is
    # straight to its left: a quarter turn counter-clockwise (positive).
    error = page.evaluate(
        "() => law.steeringError({x: 100, y: 240, w: 640, h: 480},"
        " {x: 5.544445, y: 5.544445, theta: Math.PI / 2})"
    )
    assert error == pytest.approx(math.pi / 2, abs=1e-6)


@pytest.mark.parametrize("profile", PROFILE_NAMES)
def test_controller_timeline_matches_the_python_agent(page: Page, profile: str) -> None:
    # One scripted session on a fake clock (s, on both sides): goals, a moving turtle, ticks,
    # a pause long enough for a timeout (and for follow, a search), a goal burst inside the
    # command-rate cap, and stops.
    events: list[tuple[str, float, dict[str, float] | None]] = []
    # With a face's box, far and near (only the onboard law reads it).
    goals = [
        {"x": 100.0, "y": 240.0, "w": W, "h": H, "boxH": 40.0, "targetHeightM": 0.24},
        {"x": 600.0, "y": 60.0, "w": W, "h": H, "boxH": 150.0, "targetHeightM": 0.24},
    ]
    t = 0.0
    for step in range(130):
        t = step * 0.037
        if step < 65 and step % 3 == 0:
            goal = {**goals[(step // 21) % 2], "seq": step, "frame": 1000 + step}
            events.append(("goal", t, goal))
            if step % 9 == 0:  # a second goal right behind the first: rate-capped
                events.append(("goal", t + 0.004, {**goal, "seq": step + 1}))
        pose = {"x": 5.544445 + 0.01 * step, "y": 5.544445 - 0.006 * step, "theta": 0.02 * step}
        events.append(("pose", t + 0.0053, pose))
        events.append(("tick", t + 0.0107, None))
    events.append(("goal", t + 0.1, {**goals[0], "seq": 500, "frame": 1500}))
    events.append(("stop", t + 0.15, None))
    events.append(("stop", t + 0.2, None))

    js = page.evaluate(
        """([profile, events]) => {
             const c = new control.Controller(law, law.profiles[profile]);
             return events.map(([kind, t, arg]) => {
               const twist = kind === 'goal' ? c.goal(arg, t) : kind === 'pose' ? c.pose(arg, t)
                 : kind === 'tick' ? c.tick(t) : c.stop();
               const until = c.untilTimeout(t);
               return [
                 twist === null ? null
                   : [twist.linear, twist.angular, twist.topShare ?? 1, twist.seq],
                 until,
               ];
             });
           }""",
        [profile, events],
    )
    controller = control.Controller(PROFILES[profile])
    expected: list[list[float | int | None] | None] = []
    untils: list[float | None] = []
    for kind, t, arg in events:
        if kind == "goal":
            assert arg is not None
            twist = controller.goal(
                control.Goal(
                    arg["x"],
                    arg["y"],
                    int(arg["w"]),
                    int(arg["h"]),
                    int(arg["seq"]),
                    int(arg["frame"]),
                    box_h=arg["boxH"],
                    target_height_m=arg["targetHeightM"],
                ),
                t,
            )
        elif kind == "pose":
            assert arg is not None
            twist = controller.pose(control.Pose(**arg), t)
        elif kind == "tick":
            twist = controller.tick(t)
        else:
            twist = controller.stop()
        expected.append(None if twist is None else [*wanted(twist), twist.seq])
        untils.append(controller.until_timeout(t))
    published = [e for e in expected if e is not None]
    assert any(e[1] != 0 for e in published), "the script never drove the turtle"
    assert any(e[:2] == [0.0, 0.0] and e[3] is None for e in published), "never stopped"
    if profile in ("follow", "onboard"):
        assert any(e[0] != 0 for e in published), f"{profile} never drove forward or back"
        assert any(e[3] is None and e[1] != 0 for e in published), f"{profile} never searched"
        assert any(0 < e[2] < 1 for e in published), f"{profile} never drove off-axis"
    assert len(js) == len(expected)
    # Both sides agree on when the goal timeout falls due (the ticker wakes up for it).
    assert [until for _, until in js] == pytest.approx(untils, abs=1e-12)
    for (got, _), want in zip(js, expected, strict=True):
        if want is None:
            assert got is None
        else:
            assert got is not None
            assert got[:3] == pytest.approx(want[:3], abs=1e-12) and got[3] == want[3]


def test_the_onboard_law_matches_the_python_agent(page: Page) -> None:
    # Through the diffdrive robot's 60° camera: columns across the frame, boxes near and far (and
    # none), goals that arrived at other headings than the pose's (the turn since is taken off),
    # faces that walk round the robot (their drift, led by their frame's age).
    profile = PROFILES["onboard"]
    cases: list[dict[str, Any]] = [
        {
            "goal": {
                "x": x, "y": 200.0, "w": W, "h": H, "boxH": box_h,
                "targetHeightM": None if box_h is None else 0.24, "heading": heading,
                "drift": drift, "age": age,
            },
            "pose": {"x": 1.0, "y": 3.0, "theta": theta},
        }
        for x in (0.0, 100.0, 300.0, 319.5, 320.0, 321.0, 340.0, 500.0, 640.0)
        for box_h in (None, 30.0, 111.0, 300.0)
        for heading, theta in ((None, 0.0), (0.0, 0.0), (0.2, 0.5), (3.0, -3.0), (-1.0, -1.3))
        for drift, age in ((0.0, 0.0), (0.5, 0.12), (-2.4, 0.3))
    ]  # fmt: skip
    js: list[dict[str, Any]] = page.evaluate(
        """([cases, profile]) => cases.map(({ goal, pose }) => ({
             bearing: law.pixelBearing(goal.x, goal.w, profile.hfov),
             range: goal.boxH === null ? null
               : law.targetRange(goal.boxH, goal.targetHeightM, goal.w, profile.hfov),
             command: law.lawOf(profile)(goal, pose, profile),
           }))""",
        [cases, to_json(profile)],
    )
    for case, got in zip(cases, js, strict=True):
        g, p = case["goal"], case["pose"]
        goal = control.Goal(
            g["x"], g["y"], W, H, box_h=g["boxH"], target_height_m=g["targetHeightM"],
            heading=g["heading"], drift=g["drift"], age=g["age"],
        )  # fmt: skip
        bearing = control.pixel_bearing(goal.x, goal.w, profile.hfov)
        assert got["bearing"] == pytest.approx(bearing, abs=1e-12), case
        if goal.box_h is not None:
            expected_range = control.target_range(goal.box_h, 0.24, goal.w, profile.hfov)
            assert got["range"] == pytest.approx(expected_range, abs=1e-12), case
        expected = wanted(control.onboard_law(goal, control.Pose(**p), profile))
        assert command(got["command"]) == pytest.approx(expected, abs=1e-12), case
