"""The robot description (app/protocol/robot.py): presets, description files good and bad,
the types a robot is driven in, its messages, and the heading of an Odometry's quaternion."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from app.protocol.robot import (
    PRESETS,
    TURTLESIM,
    Robot,
    RobotError,
    detect,
    load,
    pose_of,
    robot_named,
    velocity_message,
    yaw_of,
)

ROVER = """
name = "rover"

[velocity]
topic = "/base/cmd_vel"
type = "geometry_msgs/TwistStamped"
frame_id = "base_footprint"

[pose]
topic = "odom"
type = "nav_msgs/msg/Odometry"

[camera]
topic = "/front/image_raw"
type = "sensor_msgs/Image"
hfov_deg = 87

[limits]
max_linear = 0.5
max_angular = 1
linear_accel = 0.8
angular_accel = inf
"""


VELOCITY_TABLE = ROVER[ROVER.index("[velocity]") : ROVER.index("[pose]")]


def write(tmp_path: Path, text: str, name: str = "rover.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_file_describes_a_robot(tmp_path: Path) -> None:
    robot = load(write(tmp_path, ROVER))
    assert robot.name == "rover"
    assert (robot.velocity.topic, robot.velocity.type, robot.velocity.frame_id) == (
        "/base/cmd_vel",
        "geometry_msgs/TwistStamped",
        "base_footprint",
    )
    # A relative topic is the root namespace's; a ROS 2 spelling of a type is read back.
    assert (robot.pose.topic, robot.pose.type) == ("/odom", "nav_msgs/Odometry")
    assert robot.camera is not None
    assert (robot.camera.topic, robot.camera.type, robot.camera.hfov_deg) == (
        "/front/image_raw",
        "sensor_msgs/Image",
        87.0,
    )
    assert robot.limits.max_angular == 1.0 and robot.limits.angular_accel == math.inf
    assert not robot.turtlesim and robot.teleport_service is None


def test_a_minimal_file_takes_its_name_from_the_file_and_has_no_camera(tmp_path: Path) -> None:
    text = (
        ROVER.split("[camera]")[0].replace('name = "rover"', "") + ROVER.split("hfov_deg = 87")[1]
    )
    text = text.replace('frame_id = "base_footprint"\n', "")
    robot = load(write(tmp_path, text, "my-base.toml"))
    assert robot.name == "my-base"
    assert robot.camera is None
    assert robot.velocity.frame_id == "base_link"  # a TwistStamped's default frame


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
    assert robot_named("turtlebot3") is burger


@pytest.mark.parametrize(
    ("change", "needles"),
    [
        # unknown keys, at the top and in a table
        (('name = "rover"', 'name = "rover"\ncolour = "red"'), ["colour: unknown key"]),
        (("max_linear = 0.5", "max_linear = 0.5\nmax_lateral = 1"), ["limits.max_lateral"]),
        # wrong types
        (("max_linear = 0.5", "max_linear = 'fast'"), ["limits.max_linear", "number", "'fast'"]),
        (("max_linear = 0.5", "max_linear = true"), ["limits.max_linear", "boolean"]),
        (('topic = "odom"', "topic = 7"), ["pose.topic", "string"]),
        ((VELOCITY_TABLE, 'velocity = "/base/cmd_vel"\n'), ["velocity: must be a table"]),
        # bad values
        (("max_linear = 0.5", "max_linear = -0.5"), ["limits.max_linear", ">= 0", "-0.5"]),
        (("angular_accel = inf", "angular_accel = 0"), ["limits.angular_accel", "> 0"]),
        (("max_angular = 1", "max_angular = nan"), ["limits.max_angular", "nan"]),
        (("hfov_deg = 87", "hfov_deg = 190"), ["camera.hfov_deg", "180"]),
        (('topic = "odom"', 'topic = "my odom"'), ["pose.topic", "not a ROS topic name"]),
        # unknown message types
        (('"geometry_msgs/TwistStamped"', '"geometry_msgs/Twst"'), ["velocity.type", "Twst"]),
        (('"nav_msgs/msg/Odometry"', '"geometry_msgs/PoseStamped"'), ["pose.type", "unknown"]),
        (('"sensor_msgs/Image"', '"sensor_msgs/LaserScan"'), ["camera.type", "LaserScan"]),
        # missing keys and tables
        (('topic = "/base/cmd_vel"', ""), ["velocity.topic", "missing"]),
        (('topic = "odom"', ""), ["pose.topic", "missing"]),
        (("linear_accel = 0.8", ""), ["limits.linear_accel", "missing"]),
        (("[limits]", "[limited]"), ["limited", "unknown key"]),
        # a header only a TwistStamped has
        (('"geometry_msgs/TwistStamped"', '"geometry_msgs/Twist"'), ["velocity.frame_id"]),
    ],
)
def test_a_bad_file_is_one_line_naming_the_key(
    tmp_path: Path, change: tuple[str, str], needles: list[str]
) -> None:
    assert change[0] in ROVER
    path = write(tmp_path, ROVER.replace(change[0], change[1], 1))
    with pytest.raises(RobotError) as raised:
        load(path)
    message = str(raised.value)
    assert "\n" not in message
    assert str(path) in message
    for needle in needles:
        assert needle in message, message


def test_a_file_that_is_not_toml_or_not_there(tmp_path: Path) -> None:
    with pytest.raises(RobotError, match=r"not TOML.*line 2"):
        load(write(tmp_path, "name = 'x'\n[velocity\n"))
    with pytest.raises(RobotError, match="no robot preset named 'rover3'.*no such file"):
        robot_named("rover3")


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
    assert isinstance(robot_named("turtlesim"), Robot)
