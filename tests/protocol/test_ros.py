"""ROS flavours: every type name in one table, and picking the types for a robot."""

from __future__ import annotations

import pytest

from app.protocol.page import to_json
from app.protocol.ros import ROS_CONFIG, TYPES, canonical, spell, spellings


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
    ("flavour", "short", "spelled"),
    [
        ("1", "nav_msgs/Odometry", "nav_msgs/Odometry"),
        ("2", "geometry_msgs/TwistStamped", "geometry_msgs/msg/TwistStamped"),
        ("jazzy", "sensor_msgs/CompressedImage", "sensor_msgs/msg/CompressedImage"),
        ("jazzy", "turtlesim/Pose", "turtlesim_msgs/msg/Pose"),
    ],
)
def test_a_message_type_is_spelled_per_flavour_and_read_back(
    flavour: str, short: str, spelled: str
) -> None:
    assert spell(flavour, short) == spelled  # type: ignore[arg-type]
    assert canonical(spelled) == short


@pytest.mark.parametrize("junk", ["", "Twist", "geometry_msgs/srv/Twist", "a/b/c/d", "/Twist"])
def test_what_is_no_message_type_has_no_short_name(junk: str) -> None:
    assert canonical(junk) is None


def test_page_config_carries_the_whole_table() -> None:
    config = to_json(ROS_CONFIG)
    assert config["default"] == "2"
    assert config["detectTimeoutS"] == 3.0
    types = config["types"]
    assert isinstance(types, dict)
    assert types["jazzy"]["pose"] == "turtlesim_msgs/msg/Pose"
    assert types["1"]["teleportAbsolute"] == "turtlesim/TeleportAbsolute"
    assert config["settings"] == ["auto", "1", "2", "jazzy"]
