"""The vehicle page's robot messages (js/core/robot.js) and type choice (js/core/rosflavour.js)
answer as app/protocol/robot.py does: velocity commands in both types and flavours, the pose of
both pose messages, the yaw of quaternions in every quadrant and of any length, and the types
picked from what a robot's rosapi reports. The rules are stated in tests/protocol/test_robot.py;
the quaternion's here again, on the JS side."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Page

from app.protocol.page import robot_config, to_json
from app.protocol.robot import PRESETS, detect, pose_of, velocity_message, yaw_of
from app.protocol.ros import ROS_CONFIG
from tests.helpers.served_page import served_page

pytestmark = [pytest.mark.browser]

IMPORT = """async () => {
  window.robot = await import('/static/js/core/robot.js');
  window.rosflavour = await import('/static/js/core/rosflavour.js');
}"""


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with served_page() as opened:
        opened.evaluate(IMPORT)
        yield opened


def quaternion(yaw: float, scale: float) -> list[float]:
    return [0.0, 0.0, scale * math.sin(yaw / 2), scale * math.cos(yaw / 2)]


YAWS = [0.3, 2.0, -2.5, -0.7, math.pi / 2, -math.pi / 2, 0.0, math.pi]
QUATERNIONS = [quaternion(yaw, scale) for yaw in YAWS for scale in (1.0, 0.01, 37.0, -2.0)] + [
    [0.0, 0.0, 0.0, 0.0],
    [0.1, -0.2, 0.3, 0.9],  # tilted
    [0.0, 0.0, -1.0, 0.0],  # a half turn, the other way
]


def test_the_yaw_of_quaternions_in_every_quadrant_at_any_length(page: Page) -> None:
    # Through the odometry reader, the public way in: the pose's heading is the yaw.
    got = page.evaluate(
        """qs => qs.map(([x, y, z, w]) => robot.poseOf('nav_msgs/Odometry', {
             pose: { pose: { position: { x: 0, y: 0 }, orientation: { x, y, z, w } } },
           })?.theta ?? null)""",
        QUATERNIONS,
    )
    for q, have in zip(QUATERNIONS, got, strict=True):
        want = yaw_of(*q)
        assert (have is None) == (want is None), q
        if want is not None:
            assert have == pytest.approx(want, abs=1e-12), q
    # The rule itself: the heading each quaternion was made with, whatever its length.
    for k, yaw in enumerate(YAWS):
        for have in got[4 * k : 4 * k + 4]:
            assert have == pytest.approx(yaw, abs=1e-12)
    assert got[len(YAWS) * 4] is None  # the zero quaternion has no heading


def odometry(x: Any, y: Any, q: list[Any]) -> dict[str, Any]:
    orientation = dict(zip("xyzw", q, strict=True))
    return {"pose": {"pose": {"position": {"x": x, "y": y, "z": 0}, "orientation": orientation}}}


POSES: list[tuple[str, Any]] = [
    ("nav_msgs/Odometry", odometry(1.5, -2.0, quaternion(2.5, 3.0))),
    ("nav_msgs/Odometry", odometry(1.0, 1.0, [0, 0, 0, 0])),
    ("nav_msgs/Odometry", {"pose": {"pose": {"position": {"x": 1}}}}),
    ("nav_msgs/Odometry", odometry("left", 1.0, quaternion(0.5, 1.0))),
    ("turtlesim/Pose", {"x": 5.5, "y": 1, "theta": -0.5, "linear_velocity": 0}),
    ("turtlesim/Pose", {"x": 5.5, "y": 1}),
]


def test_the_pose_of_pose_messages(page: Page) -> None:
    got = page.evaluate("cases => cases.map(([kind, m]) => robot.poseOf(kind, m))", POSES)
    for (kind, message), have in zip(POSES, got, strict=True):
        want = pose_of(kind, message)  # type: ignore[arg-type]
        if want is None:
            assert have is None, message
        else:
            assert [have["x"], have["y"], have["theta"]] == pytest.approx(list(want), abs=1e-12)


@pytest.mark.parametrize("flavour", ["1", "2", "jazzy"])
@pytest.mark.parametrize("kind", ["geometry_msgs/Twist", "geometry_msgs/TwistStamped"])
def test_velocity_messages(page: Page, kind: str, flavour: str) -> None:
    for stamp in (1_700_000_000.25, 12.999999999, 0.0):
        args = [kind, flavour, 0.2, -1.5, stamp, "base_footprint"]
        got = page.evaluate("args => robot.velocityMessage(...args)", args)
        assert got == velocity_message(*args)  # type: ignore[arg-type]


REPORTS = [
    ("turtlesim", "turtlesim_msgs/msg/Pose", "geometry_msgs/msg/Twist", "auto"),
    ("turtlesim", "turtlesim/msg/Pose", None, "1"),
    ("turtlesim", None, None, "jazzy"),
    ("turtlesim", "", None, "1"),
    ("turtlebot3", "nav_msgs/Odometry", "geometry_msgs/Twist", "auto"),
    ("turtlebot3", "nav_msgs/msg/Odometry", "geometry_msgs/msg/TwistStamped", "1"),
    ("turtlebot3", "nav_msgs/msg/Odometry", "ackermann_msgs/msg/AckermannDrive", "auto"),
    ("turtlebot3", None, None, "jazzy"),
    ("diffdrive", None, "geometry_msgs/TwistStamped", "auto"),
]


def test_the_types_picked_from_what_the_robot_reports(page: Page) -> None:
    cases = [
        [to_json(robot_config(PRESETS[name])), setting, pose, velocity]
        for name, pose, velocity, setting in REPORTS
    ]
    got = page.evaluate(
        """([rosTypes, cases]) => cases.map(([robot, setting, pose, velocity]) =>
             rosflavour.pickTypes(rosTypes, robot, setting, pose, velocity))""",
        [to_json(ROS_CONFIG), cases],
    )
    for (name, pose, velocity, setting), have in zip(REPORTS, got, strict=True):
        want = detect(PRESETS[name], pose, velocity, setting)  # type: ignore[arg-type]
        assert have == {
            "flavour": want.flavour,
            "fromRobot": want.from_robot,
            "pose": want.pose,
            "velocity": want.velocity,
            "velocityKind": want.velocity_kind,
            "teleport": ROS_CONFIG.types[want.flavour].teleport_absolute,
        }, (name, pose, velocity, setting)
