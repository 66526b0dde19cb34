"""The robot description (app/protocol/robot.py): presets, the types a robot is driven in, its
messages, and the heading of an Odometry's quaternion (description files: test_robot_file.py)."""

from __future__ import annotations

import math

import pytest

from app.protocol.robot import (
    PRESETS,
    TURTLESIM,
    Robot,
    detect,
    pose_of,
    velocity_message,
    yaw_of,
)


def test_the_presets() -> None:
    turtlesim, diffdrive, burger = PRESETS["turtlesim"], PRESETS["diffdrive"], PRESETS["turtlebot3"]
    assert turtlesim is TURTLESIM and turtlesim.turtlesim
    assert (turtlesim.velocity.topic, turtlesim.pose.topic) == ("/turtle1/cmd_vel", "/turtle1/pose")
    assert turtlesim.teleport_service == "/turtle1/teleport_absolute"
    assert turtlesim.camera is None
    # No profile commands more than 4 m/s or 5 rad/s, and turtlesim applies a command at once.
    assert (turtlesim.limits.max_linear, turtlesim.limits.max_angular) == (4.0, 5.0)
    assert turtlesim.limits.linear_accel == turtlesim.limits.angular_accel == math.inf
    assert (diffdrive.velocity.topic, diffdrive.pose.topic) == ("/cmd_vel", "/odom")
    assert diffdrive.camera is not None and diffdrive.camera.hfov_deg == 60.0
    assert diffdrive.camera.topic == "/camera/image/compressed"
    # TurtleBot3 Burger: 0.22 m/s and 2.84 rad/s (ROBOTIS e-Manual).
    assert (burger.limits.max_linear, burger.limits.max_angular) == (0.22, 2.84)
    assert burger.pose.type == "nav_msgs/Odometry" and not burger.turtlesim


def test_detect_learns_the_flavour_from_the_pose_type_the_robot_reports() -> None:
    burger = PRESETS["turtlebot3"]
    ros1 = detect(burger, "nav_msgs/Odometry", "geometry_msgs/Twist", "auto")
    assert (ros1.flavour, ros1.pose, ros1.velocity, ros1.from_robot) == (
        "1",
        "nav_msgs/Odometry",
        "geometry_msgs/Twist",
        True,
    )
    ros2 = detect(burger, "nav_msgs/msg/Odometry", None, "1")
    assert (ros2.flavour, ros2.velocity, ros2.velocity_kind) == (
        "2",
        "geometry_msgs/msg/Twist",
        "geometry_msgs/Twist",
    )
    # No answer: the setting decides, and the description's type is spelled its way.
    silent = detect(burger, None, None, "jazzy")
    assert (silent.flavour, silent.pose, silent.from_robot) == (
        "jazzy",
        "nav_msgs/msg/Odometry",
        False,
    )
    assert detect(burger, "", None, "auto").flavour == "2"


def test_the_velocity_type_the_robot_reports_wins_over_the_description() -> None:
    burger = PRESETS["turtlebot3"]  # described as a Twist
    stamped = detect(burger, "nav_msgs/msg/Odometry", "geometry_msgs/msg/TwistStamped", "auto")
    assert (stamped.velocity, stamped.velocity_kind) == (
        "geometry_msgs/msg/TwistStamped",
        "geometry_msgs/TwistStamped",
    )
    # A type the pilot cannot publish leaves the description's.
    odd = detect(burger, "nav_msgs/msg/Odometry", "ackermann_msgs/msg/AckermannDrive", "auto")
    assert (odd.velocity, odd.velocity_kind) == ("geometry_msgs/msg/Twist", "geometry_msgs/Twist")


@pytest.mark.parametrize(
    ("pose", "flavour"),
    [("turtlesim/Pose", "1"), ("turtlesim/msg/Pose", "2"), ("turtlesim_msgs/msg/Pose", "jazzy")],
)
def test_a_turtlesim_is_still_told_apart_by_its_pose_type(pose: str, flavour: str) -> None:
    types = detect(TURTLESIM, pose, None, "auto")
    assert (types.flavour, types.pose, types.from_robot) == (flavour, pose, True)
    assert types.velocity == (
        "geometry_msgs/Twist" if flavour == "1" else "geometry_msgs/msg/Twist"
    )


def test_a_twist_is_a_twist_and_a_twist_stamped_carries_its_stamp_and_frame() -> None:
    twist = velocity_message("geometry_msgs/Twist", "2", 0.2, -1.5, 1_700_000_000.5, "")
    assert twist == {
        "linear": {"x": 0.2, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": -1.5},
    }
    ros2 = velocity_message("geometry_msgs/TwistStamped", "2", 0.2, -1.5, 1_700_000_000.25, "base")
    assert ros2["twist"] == twist
    assert ros2["header"] == {
        "stamp": {"sec": 1_700_000_000, "nanosec": 250_000_000},
        "frame_id": "base",
    }
    ros1 = velocity_message("geometry_msgs/TwistStamped", "1", 0.2, -1.5, 12.75, "base")
    assert ros1["header"]["stamp"] == {"secs": 12, "nsecs": 750_000_000}


def quaternion(yaw: float, scale: float = 1.0) -> tuple[float, float, float, float]:
    """A rotation by ``yaw`` about z, as (x, y, z, w), ``scale`` times a unit quaternion."""
    return (0.0, 0.0, scale * math.sin(yaw / 2), scale * math.cos(yaw / 2))


@pytest.mark.parametrize("yaw", [0.3, 2.0, -2.5, -0.7, math.pi / 2, -math.pi / 2, 0.0])
@pytest.mark.parametrize("scale", [1.0, 0.01, 37.0, -2.0])
def test_the_yaw_of_a_quaternion_in_every_quadrant_at_any_length(yaw: float, scale: float) -> None:
    # Headings in all four quadrants; a quaternion of any length (or sign: q and −q are one
    # rotation) gives the same heading.
    assert yaw_of(*quaternion(yaw, scale)) == pytest.approx(yaw, abs=1e-12)


def test_the_yaw_of_a_tilted_robot_is_its_heading() -> None:
    # Yaw 1.0 then a roll of 0.2 about the robot's own x axis (a ramp): the heading stays 1.0.
    cy, sy, cr, sr = math.cos(0.5), math.sin(0.5), math.cos(0.1), math.sin(0.1)
    q = (cy * sr, sy * sr, sy * cr, cy * cr)
    assert yaw_of(*q) == pytest.approx(1.0, abs=1e-12)
    # Behind the robot: +π, the project's convention for wrapping.
    assert yaw_of(*quaternion(math.pi)) == pytest.approx(math.pi)


@pytest.mark.parametrize(
    "q", [(0.0, 0.0, 0.0, 0.0), (0.0, 0.0, math.nan, 1.0), (math.inf, 0, 0, 1)]
)
def test_a_quaternion_with_no_heading_has_no_yaw(q: tuple[float, float, float, float]) -> None:
    assert yaw_of(*q) is None


def odometry(x: float, y: float, q: tuple[float, float, float, float]) -> dict[str, object]:
    qx, qy, qz, qw = q
    return {
        "header": {"frame_id": "odom"},
        "child_frame_id": "base_link",
        "pose": {
            "pose": {
                "position": {"x": x, "y": y, "z": 0.0},
                "orientation": {"x": qx, "y": qy, "z": qz, "w": qw},
            },
            "covariance": [0.0] * 36,
        },
    }


def test_the_pose_of_a_pose_message() -> None:
    assert pose_of("nav_msgs/Odometry", odometry(1.5, -2.0, quaternion(2.5, 3.0))) == (
        1.5,
        -2.0,
        pytest.approx(2.5),
    )
    assert pose_of("turtlesim/Pose", {"x": 5.5, "y": 1, "theta": -0.5}) == (5.5, 1.0, -0.5)
    assert pose_of("nav_msgs/Odometry", odometry(1.0, 1.0, (0.0, 0.0, 0.0, 0.0))) is None
    assert pose_of("nav_msgs/Odometry", {"pose": {"pose": {"position": {"x": 1}}}}) is None
    assert pose_of("turtlesim/Pose", {"x": "left", "y": 1, "theta": 0}) is None


def test_a_robot_is_frozen() -> None:
    with pytest.raises(AttributeError):
        TURTLESIM.name = "other"  # type: ignore[misc]
    assert isinstance(PRESETS["turtlesim"], Robot)
