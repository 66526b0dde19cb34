"""A differential-drive robot on a walled floor, as plain synchronous code.

It takes ``cmd_vel`` as a differential-drive base does -- ``linear.x`` forward and
``angular.z`` counter-clockwise, nothing sideways -- and holds a command until the next one or
until :attr:`DiffDrive.COMMAND_TIMEOUT_S` passes without one (then it stops, as turtlesim
does). The owner calls :meth:`DiffDrive.step` once per fixed tick; the clock for the timeout
is injected, so tests drive time themselves. The robot is a disc that the walls stop: driven
into one it slides along it, never through.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from app.protocol.angles import wrap_angle
from app.protocol.robot import PRESETS, Robot

# The robot as its description tells the agent and the vehicle page of it: its topics, its
# camera's field of view, its top speeds.
DESCRIPTION: Final[Robot] = PRESETS["diffdrive"]
assert DESCRIPTION.camera is not None, "the simulated robot has its camera"
# The robot's camera: its horizontal field of view, and the height of the mast it sits on,
# looking level -- a face at head height is in view from about a metre away (a camera at a
# TurtleBot's 0.2 m would see only legs up close).
CAMERA_HFOV: Final = math.radians(DESCRIPTION.camera.hfov_deg)
CAMERA_HEIGHT_M: Final = 1.3
# Below this turn rate a tick's arc is taken as a straight line (the arc's formula divides by it).
_STRAIGHT_RAD_S: Final = 1e-9


@dataclass(frozen=True)
class RobotState:
    """The robot's pose and the velocities it is driving at (what ``/odom`` reports)."""

    x: float
    y: float
    yaw: float
    linear: float
    angular: float


class DiffDrive:
    """A differential-drive robot of radius :attr:`RADIUS_M` in a ``width`` by ``depth`` arena."""

    TICK_S: Final = 0.016
    COMMAND_TIMEOUT_S: Final = 1.0
    RADIUS_M: Final = 0.2

    def __init__(
        self,
        width: float,
        depth: float,
        x: float,
        y: float,
        yaw: float,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if width <= 2 * self.RADIUS_M or depth <= 2 * self.RADIUS_M:
            raise ValueError(f"a {width} m by {depth} m arena is too small for the robot")
        self._clock = clock
        self.width, self.depth = width, depth
        self.x, self.y = self._inside(x, width), self._inside(y, depth)
        self.yaw = wrap_angle(yaw)
        self.linear = self.angular = 0.0
        self._last_command = clock()

    def cmd_vel(self, linear_x: float, angular_z: float) -> None:
        """Drive at ``linear_x`` m/s and ``angular_z`` rad/s until the next command or the
        timeout, each capped at the robot's top speed (as a real base's driver caps them);
        ``ValueError`` for a velocity that is not finite."""
        for label, value in (("linear.x", linear_x), ("angular.z", angular_z)):
            if not math.isfinite(value):
                raise ValueError(f"{label} must be finite, got {value}")
        limits = DESCRIPTION.limits
        self.linear = min(max(float(linear_x), -limits.max_linear), limits.max_linear)
        self.angular = min(max(float(angular_z), -limits.max_angular), limits.max_angular)
        self._last_command = self._clock()

    def step(self) -> None:
        """Advance one fixed tick along the arc the velocities describe, whatever the wall
        time since the last one; stopped first if no command came for the timeout."""
        if self._clock() - self._last_command > self.COMMAND_TIMEOUT_S:
            self.linear = self.angular = 0.0
        v, w, dt = self.linear, self.angular, self.TICK_S
        yaw = self.yaw + w * dt
        if abs(w) < _STRAIGHT_RAD_S:
            dx, dy = v * dt * math.cos(self.yaw), v * dt * math.sin(self.yaw)
        else:
            dx = v / w * (math.sin(yaw) - math.sin(self.yaw))
            dy = -v / w * (math.cos(yaw) - math.cos(self.yaw))
        self.x = self._inside(self.x + dx, self.width)
        self.y = self._inside(self.y + dy, self.depth)
        self.yaw = wrap_angle(yaw)

    def state(self) -> RobotState:
        """Pose and velocities as this tick left them."""
        return RobotState(self.x, self.y, self.yaw, self.linear, self.angular)

    def _inside(self, value: float, extent: float) -> float:
        return min(max(value, self.RADIUS_M), extent - self.RADIUS_M)
