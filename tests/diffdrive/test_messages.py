"""The simulated robot's messages: odometry with the yaw as a quaternion, JPEG frames in base64,
stamps and headers as each ROS flavour spells them."""

from __future__ import annotations

import base64
import math

import pytest

from app.diffdrive.messages import compressed_image, odometry, stamp, yaw_quaternion
from app.diffdrive.robot import RobotState


@pytest.mark.parametrize("yaw", [0.0, 0.3, math.pi / 2, -2.5, math.pi])
def test_the_quaternion_turns_the_x_axis_to_the_yaw(yaw: float) -> None:
    q = yaw_quaternion(yaw)
    assert q["x"] == q["y"] == 0.0
    assert q["z"] ** 2 + q["w"] ** 2 == pytest.approx(1.0)
    # The x axis rotated by q: (1 - 2z², 2wz) for a rotation about z.
    heading = math.atan2(2 * q["w"] * q["z"], 1 - 2 * q["z"] ** 2)
    assert math.remainder(heading - yaw, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)


def test_odometry_carries_the_pose_and_the_velocities() -> None:
    state = RobotState(3.25, 1.5, math.pi / 2, 0.4, -0.2)
    message = odometry("2", state, 1700000000.25, 7)
    assert message["header"] == {
        "stamp": {"sec": 1700000000, "nanosec": 250000000},
        "frame_id": "odom",
    }
    assert message["child_frame_id"] == "base_link"
    pose = message["pose"]["pose"]
    assert pose["position"] == {"x": 3.25, "y": 1.5, "z": 0.0}
    assert pose["orientation"]["z"] == pytest.approx(math.sqrt(0.5))
    twist = message["twist"]["twist"]
    assert twist["linear"]["x"] == 0.4 and twist["angular"]["z"] == -0.2
    assert len(message["pose"]["covariance"]) == len(message["twist"]["covariance"]) == 36


def test_ros1_headers_have_a_sequence_number_and_secs() -> None:
    state = RobotState(1.0, 1.0, 0.0, 0.0, 0.0)
    assert odometry("1", state, 12.5, 41)["header"] == {
        "seq": 41,
        "stamp": {"secs": 12, "nsecs": 500000000},
        "frame_id": "odom",
    }
    assert "seq" not in odometry("jazzy", state, 12.5, 41)["header"]


def test_a_stamp_never_rounds_up_to_a_whole_billion_nanoseconds() -> None:
    assert stamp("2", 5.9999999999) == {"sec": 5, "nanosec": 999999999}


def test_a_compressed_image_holds_the_jpeg_in_base64() -> None:
    jpeg = b"\xff\xd8\xff\xe0 not really a picture \xff\xd9"
    message = compressed_image("2", jpeg, 3.0, 1)
    assert message["format"] == "jpeg"
    assert message["header"]["frame_id"] == "camera"
    assert base64.b64decode(message["data"]) == jpeg
