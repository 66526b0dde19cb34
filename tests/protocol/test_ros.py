"""ROS flavours: every type name in one table, and picking the types for a robot."""

from __future__ import annotations

import pytest

from app.protocol.page import to_json
from app.protocol.ros import ROS_CONFIG, TYPES, detect, spellings


def test_each_flavour_spells_turtlesim_types_its_own_way() -> None:
    assert (TYPES["1"].pose, TYPES["1"].twist) == ("turtlesim/Pose", "geometry_msgs/Twist")
    assert (TYPES["2"].pose, TYPES["2"].spawn) == ("turtlesim/msg/Pose", "turtlesim/srv/Spawn")
    assert (TYPES["jazzy"].pose, TYPES["jazzy"].set_pen) == (
        "turtlesim_msgs/msg/Pose",
        "turtlesim_msgs/srv/SetPen",
    )
    # Only turtlesim's own interfaces moved in Jazzy.
    assert TYPES["jazzy"].twist == TYPES["2"].twist == "geometry_msgs/msg/Twist"
    assert TYPES["jazzy"].empty == "std_srvs/srv/Empty"
    assert TYPES["1"].rosapi("Topics") == "rosapi/Topics"
    assert TYPES["2"].rosapi("Topics") == "rosapi_msgs/srv/Topics"


def test_ros2_rosbridge_also_takes_the_short_spelling() -> None:
    assert spellings("1", "turtlesim/Pose") == {"turtlesim/Pose"}
    assert spellings("2", "turtlesim/msg/Pose") == {"turtlesim/msg/Pose", "turtlesim/Pose"}


@pytest.mark.parametrize(
    ("pose", "twist", "setting", "flavour", "from_robot"),
    [
        ("turtlesim/Pose", "geometry_msgs/Twist", "auto", "1", True),
        ("turtlesim/msg/Pose", None, "auto", "2", True),
        ("turtlesim_msgs/msg/Pose", "geometry_msgs/msg/Twist", "1", "jazzy", True),
        (None, None, "jazzy", "jazzy", False),
        ("", None, "1", "1", False),
        (None, None, "auto", "2", False),
        ("some_pkg/msg/Other", None, "auto", "2", False),
    ],
)
def test_detect_prefers_the_robots_answer_then_the_setting(
    pose: str | None, twist: str | None, setting: str, flavour: str, from_robot: bool
) -> None:
    detected = detect(pose, twist, setting)  # type: ignore[arg-type]
    assert (detected.flavour, detected.from_robot) == (flavour, from_robot)
    assert detected.pose == TYPES[detected.flavour].pose
    assert detected.twist == (twist or TYPES[detected.flavour].twist)


def test_page_config_carries_the_whole_table() -> None:
    config = to_json(ROS_CONFIG)
    assert config["default"] == "2"
    assert config["detectTimeoutS"] == 3.0
    types = config["types"]
    assert isinstance(types, dict)
    assert types["jazzy"]["pose"] == "turtlesim_msgs/msg/Pose"
    assert types["1"]["teleportAbsolute"] == "turtlesim/TeleportAbsolute"
    assert config["settings"] == ["auto", "1", "2", "jazzy"]
