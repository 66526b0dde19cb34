"""What the simulated robot publishes, as rosbridge's JSON gives it to a client.

``/odom`` is a ``nav_msgs/Odometry`` in the arena's frame (``odom``: its origin the arena's
south-west corner, so the pose read from it is the arena's) with the heading as a quaternion
about z; the camera is a ``sensor_msgs/CompressedImage`` with the JPEG's bytes in base64, as
rosbridge encodes a ``uint8[]``. Stamps and headers are spelled as the ROS flavour spells them:
``secs``/``nsecs`` and a ``seq`` in ROS 1, ``sec``/``nanosec`` in ROS 2.
"""

from __future__ import annotations

import base64
import math
from typing import Any, Final

from app.diffdrive.robot import RobotState
from app.protocol.ros import RosFlavour

Json = dict[str, Any]

ODOM_FRAME: Final = "odom"
BASE_FRAME: Final = "base_link"
CAMERA_FRAME: Final = "camera"
# A pose and a twist known exactly: the simulator's odometry has no error to declare.
_NO_COVARIANCE: Final = [0.0] * 36


def yaw_quaternion(yaw: float) -> Json:
    """The rotation by ``yaw`` about z, as a ``geometry_msgs/Quaternion``."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def stamp(flavour: RosFlavour, seconds: float) -> Json:
    """``seconds`` since the epoch as the flavour's time message."""
    whole = math.floor(seconds)
    nanoseconds = min(999_999_999, round((seconds - whole) * 1e9))
    if flavour == "1":
        return {"secs": whole, "nsecs": nanoseconds}
    return {"sec": whole, "nanosec": nanoseconds}


def header(flavour: RosFlavour, seconds: float, frame_id: str, seq: int) -> Json:
    """A ``std_msgs/Header``; ``seq`` only where the flavour has it (ROS 1)."""
    message: Json = {"stamp": stamp(flavour, seconds), "frame_id": frame_id}
    if flavour == "1":
        message = {"seq": seq, **message}
    return message


def odometry(flavour: RosFlavour, state: RobotState, seconds: float, seq: int) -> Json:
    """The robot's ``nav_msgs/Odometry`` at ``seconds``: its pose in the arena and the
    velocities it drives at, in its own frame."""
    return {
        "header": header(flavour, seconds, ODOM_FRAME, seq),
        "child_frame_id": BASE_FRAME,
        "pose": {
            "pose": {
                "position": {"x": state.x, "y": state.y, "z": 0.0},
                "orientation": yaw_quaternion(state.yaw),
            },
            "covariance": _NO_COVARIANCE,
        },
        "twist": {
            "twist": {
                "linear": {"x": state.linear, "y": 0.0, "z": 0.0},
                "angular": {"x": 0.0, "y": 0.0, "z": state.angular},
            },
            "covariance": _NO_COVARIANCE,
        },
    }


def compressed_image(flavour: RosFlavour, jpeg: bytes, seconds: float, seq: int) -> Json:
    """A ``sensor_msgs/CompressedImage`` holding ``jpeg``, taken at ``seconds``."""
    return {
        "header": header(flavour, seconds, CAMERA_FRAME, seq),
        "format": "jpeg",
        "data": base64.b64encode(jpeg).decode("ascii"),
    }
