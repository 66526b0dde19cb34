"""The control law of DESIGN §5 and its two timing profiles (docs/contracts.md).

Sans-I/O: a :class:`Controller` is fed goals, poses and clock ticks and answers with the
:class:`Twist` to publish, if any. The browser vehicle page's ``control.js`` implements the same
law, so both vehicles behave alike.

Coordinate conventions: image pixels have their origin at the top-left corner with y growing
downward; the turtlesim terrain has its origin at the bottom-left corner with y growing upward.
A goal pixel is therefore flipped vertically when mapped to the terrain: a face in the top half
of the frame is a target in the upper half of the terrain, i.e. the turtle looks "up" (θ > 0).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from app.protocol.angles import wrap_angle
from app.protocol.constants import TERRAIN_CENTRE

# Below this distance the direction to the target is meaningless (the thesis's turtle sits at
# the terrain centre, which is where a goal in the middle of the frame lands).
MIN_TARGET_DISTANCE_M = 0.05


@dataclass(frozen=True)
class Pose:
    """Where the turtle is: terrain metres and heading in radians."""

    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class Goal:
    """A target pixel of a ``w``×``h`` frame, as sent by the relay."""

    x: float
    y: float
    w: int
    h: int
    seq: int | None = None
    frame: int | None = None


@dataclass(frozen=True)
class Twist:
    """A velocity command; ``seq``/``frame`` name the goal it came from (None for a stop)."""

    linear_x: float
    angular_z: float
    seq: int | None = None
    frame: int | None = None

    @property
    def is_zero(self) -> bool:
        """True for the stop command."""
        return self.linear_x == 0.0 and self.angular_z == 0.0


ZERO_TWIST = Twist(0.0, 0.0)


@dataclass(frozen=True)
class Profile:
    """How often Twists go out and how the steering error becomes an angular velocity."""

    name: str
    # Minimum time between two Twists.
    period_s: float
    # True: a Twist is computed on every pose update (closed loop); False: on the clock alone.
    on_pose: bool
    gain: float
    max_angular: float
    deadband: float
    goal_timeout_s: float


PROFILES: dict[str, Profile] = {
    "default": Profile(
        name="default",
        period_s=0.05,
        on_pose=True,
        gain=6.0,
        max_angular=4.0,
        deadband=0.01,
        goal_timeout_s=0.75,
    ),
    # The thesis publishes the latest goal every 1100 ms; turtlesim runs a command for 1 s, so
    # angular.z = e turns the turtle by e.
    "thesis": Profile(
        name="thesis",
        period_s=1.1,
        on_pose=False,
        gain=1.0,
        max_angular=math.inf,
        deadband=0.0,
        goal_timeout_s=2.5,
    ),
}


def pixel_to_terrain(x: float, y: float, w: int, h: int) -> tuple[float, float]:
    """Map a goal pixel of a ``w``×``h`` frame to terrain metres (image y flipped)."""
    return x * TERRAIN_CENTRE / (w / 2), (h - y) * TERRAIN_CENTRE / (h / 2)


def steering_error(goal: Goal, pose: Pose) -> float | None:
    """Signed turn, in (−π, π], that makes the turtle face the goal; None when undefined."""
    tx, ty = pixel_to_terrain(goal.x, goal.y, goal.w, goal.h)
    dx, dy = tx - pose.x, ty - pose.y
    if math.hypot(dx, dy) < MIN_TARGET_DISTANCE_M:
        return None
    return wrap_angle(math.atan2(dy, dx) - pose.theta)


def angular_command(error: float, profile: Profile) -> float:
    """The profile's angular velocity for a steering error."""
    if abs(error) < profile.deadband:
        return 0.0
    command = profile.gain * error
    return max(-profile.max_angular, min(profile.max_angular, command))


class Controller:
    """Turns goals into Twists with one profile; rotates in place (linear.x = 0).

    Call :meth:`goal` for each goal, :meth:`pose` for each pose update and :meth:`tick`
    regularly (every few tens of milliseconds); each returns the Twist to publish now, if any.
    After a goal timeout or :meth:`stop` exactly one zero Twist is returned, then nothing until
    the next goal.
    """

    def __init__(self, profile: Profile, clock: Callable[[], float] = time.monotonic) -> None:
        self.profile = profile
        self._clock = clock
        self._goal: Goal | None = None
        self._goal_at = 0.0
        self._pose: Pose | None = None
        self._last_publish: float | None = None

    @property
    def active(self) -> bool:
        """True while goals are arriving (the turtle is being piloted)."""
        return self._goal is not None

    def goal(self, goal: Goal) -> Twist | None:
        """Take a new goal; the thesis profile answers at once when its period has elapsed."""
        self._goal = goal
        self._goal_at = self._clock()
        return None if self.profile.on_pose else self._due()

    def pose(self, pose: Pose) -> Twist | None:
        """Take a pose update; the default profile answers with a Twist when one is due."""
        self._pose = pose
        timed_out = self._check_timeout()
        if timed_out is not None:
            return timed_out
        return self._due() if self.profile.on_pose else None

    def tick(self) -> Twist | None:
        """Check the goal timeout and, for the thesis profile, the publishing period."""
        timed_out = self._check_timeout()
        if timed_out is not None:
            return timed_out
        return None if self.profile.on_pose else self._due()

    def stop(self) -> Twist | None:
        """Piloting stopped or the relay left: one zero Twist if the turtle was being driven."""
        if self._goal is None:
            return None
        self._goal = None
        self._last_publish = None
        return ZERO_TWIST

    def _check_timeout(self) -> Twist | None:
        if self._goal is not None and self._clock() - self._goal_at > self.profile.goal_timeout_s:
            return self.stop()
        return None

    def _due(self) -> Twist | None:
        goal, pose = self._goal, self._pose
        if goal is None or pose is None:
            return None
        now = self._clock()
        if self._last_publish is not None and now - self._last_publish < self.profile.period_s:
            return None
        last = self._last_publish
        # The clock-driven profile keeps a fixed cadence (like the thesis's setInterval) instead
        # of drifting by the tick granularity; after a pause it starts a new grid.
        if not self.profile.on_pose and last is not None and now - last < 2 * self.profile.period_s:
            self._last_publish = last + self.profile.period_s
        else:
            self._last_publish = now
        error = steering_error(goal, pose)
        # No defined heading: hold still rather than keep the last turn going.
        angular = 0.0 if error is None else angular_command(error, self.profile)
        return Twist(0.0, angular, seq=goal.seq, frame=goal.frame)
