"""Every command within the robot's limits: clamped to its top speeds, ramped within its
accelerations (the robot description's :class:`~app.protocol.robot.Limits`).

Sans-I/O, like the rest of the pilot: a :class:`Limiter` is given each command with the time
(seconds, the pilot's clock) and answers with the Twist to publish now, and on the clock with
the next step of a ramp still under way. The pilot (:mod:`vehicle_agent.core.pilot`) passes every
Twist it publishes through it, autopilot and operator alike. The browser's twin is
``app/static/js/core/limits.js``; both run the pilot's shared sequences
(tests/vehicle_agent/core/pilot_sequences.py), and tests/vehicle_agent/core/test_limits.py
states the rules.

The rules:

* linear.x is clamped to ``±max_linear`` times the command's ``top_share`` (1 but where a law
  drives only as much as it faces its target, and says how much), angular.z to
  ``±max_angular``. This is the one place a robot's top speed holds a command: the laws ask for
  the speeds they want.
* Between two published Twists ``dt`` apart, linear.x changes by at most ``linear_accel·dt``
  and angular.z by at most ``angular_accel·dt``, ``dt`` counted at most one pilot tick: a robot
  that stood still for a minute may not jump to full speed. A command the ramp cannot reach at
  once is approached on every tick until it is reached or replaced.
* A stop is not ramped: the zero Twist of a stop, goal timeout, dead-man, lost link, mode change
  or released stick (a zero Twist that answers no goal) is published at once. The robot's own
  base controller brakes within what its motors can do; ramping the command down would only
  delay a safety stop, and the dead-man's contract is a stop within 0.3 s of the last command.
"""

from __future__ import annotations

import math

from app.protocol.robot import Limits
from vehicle_agent.core.control import Twist


def is_stop(twist: Twist) -> bool:
    """True for a stop: a zero Twist that answers no goal."""
    return twist.is_zero and twist.seq is None


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def _toward(current: float, target: float, accel: float, dt: float) -> float:
    """``current`` moved toward ``target`` by at most ``accel·dt`` (exactly onto it when that
    reaches, so an unlimited acceleration gives the target itself, not a rounding of it)."""
    reach = math.inf if math.isinf(accel) else accel * dt
    if abs(target - current) <= reach:
        return target
    return current + math.copysign(reach, target - current)


class Limiter:
    """The ramp between the commands a pilot computes and the Twists it publishes."""

    def __init__(self, limits: Limits, step_s: float) -> None:
        self.limits = limits
        # The longest time one ramp step may count (the pilot's tick).
        self.step_s = step_s
        # What is being published, what was asked for, and when the last Twist went out.
        self._current = Twist(0.0, 0.0)
        self._target = Twist(0.0, 0.0)
        self._at: float | None = None

    @property
    def ramping(self) -> bool:
        """True while the published Twist has not reached the command yet."""
        return (self._current.linear_x, self._current.angular_z) != (
            self._target.linear_x,
            self._target.angular_z,
        )

    def command(self, twist: Twist, now: float) -> Twist:
        """The Twist to publish now for the command ``twist``."""
        if is_stop(twist):
            self._current = self._target = twist
            self._at = now
            return twist
        # A share of 0 reaches nothing, even of a robot without a top speed (inf · 0 is NaN).
        top = self.limits.max_linear * twist.top_share if twist.top_share > 0 else 0.0
        self._target = Twist(
            _clamp(twist.linear_x, top),
            _clamp(twist.angular_z, self.limits.max_angular),
            twist.seq,
            twist.frame,
        )
        return self._step(now)

    def tick(self, now: float) -> Twist | None:
        """The ramp's next step while the command is out of reach, else None (nothing new)."""
        if not self.ramping or (self._at is not None and now <= self._at):
            return None
        return self._step(now)

    def _step(self, now: float) -> Twist:
        dt = self.step_s if self._at is None else min(max(0.0, now - self._at), self.step_s)
        current, target = self._current, self._target
        self._current = Twist(
            _toward(current.linear_x, target.linear_x, self.limits.linear_accel, dt),
            _toward(current.angular_z, target.angular_z, self.limits.angular_accel, dt),
            target.seq,
            target.frame,
        )
        self._at = now
        return self._current
