"""A robot that is not a turtle, played through a rosbridge with roslibpy: it publishes its
odometry as a TurtleBot's bringup does and records what arrives on its velocity topic. Against
the server's /rosbridge its topics are hosted ones (app/rosbridge/hosted.py)."""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import roslibpy

WAIT_S = 10.0
# Where the stand-in stands: its odometry's position and heading.
POSITION = (2.0, -1.0)
YAW = 1.0


class StandIn:
    """The robot: ``/odom``-like odometry out at 20 Hz, its velocity topic in.

    Its orientation is a quaternion twice the unit length: whoever reads it must not assume a
    normalised one.
    """

    def __init__(self, url: str, velocity: tuple[str, str], odom: str) -> None:
        self.ros = roslibpy.Ros(host=url)
        self.ros.run(timeout=WAIT_S)
        self._received: list[tuple[float, dict[str, Any]]] = []
        self._lock = threading.Lock()
        # Every command, not only the latest when two come between the rosbridge's sends.
        self.velocity = roslibpy.Topic(self.ros, *velocity, queue_length=100)
        self.velocity.subscribe(self._command)
        self.odom = roslibpy.Topic(self.ros, odom, "nav_msgs/msg/Odometry")
        self.odom.advertise()
        half = YAW / 2
        self._pose = {
            "position": {"x": POSITION[0], "y": POSITION[1], "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 2 * math.sin(half), "w": 2 * math.cos(half)},
        }
        # Both topics are hosted (so typed in rosapi) once a call made after them returns.
        topic_type = roslibpy.Service(self.ros, "/rosapi/topic_type", "rosapi/TopicType")
        reply = topic_type.call(roslibpy.ServiceRequest({"topic": velocity[0]}), timeout=WAIT_S)
        assert reply["type"] == velocity[1], reply
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._publish_odometry, daemon=True)
        self._thread.start()

    def _command(self, message: dict[str, Any]) -> None:
        with self._lock:
            self._received.append((time.monotonic(), message))

    def _publish_odometry(self) -> None:
        while not self._stop.wait(0.05):
            message = {"child_frame_id": "base_link", "pose": {"pose": self._pose}}
            self.odom.publish(roslibpy.Message(message))

    def commands(self) -> list[tuple[float, dict[str, Any]]]:
        """Every message received on the velocity topic, with when it came."""
        with self._lock:
            return list(self._received)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=WAIT_S)
        self.ros.close()


def velocities(
    commands: list[tuple[float, dict[str, Any]]], stamped: bool
) -> list[tuple[float, float, float]]:
    """(time received, linear.x, angular.z) of each command, a Twist's or a TwistStamped's."""
    out = []
    for at, message in commands:
        twist = message["twist"] if stamped else message
        out.append((at, twist["linear"]["x"], twist["angular"]["z"]))
    return out
