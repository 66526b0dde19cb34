"""The project's one angle convention, and turtlesim's, in one place.

Two wrap functions remain on purpose, and they differ only at the boundary ±π:

- :func:`wrap_angle` wraps into ``(−π, π]``: the control law's steering error and the bench's
  heading error. A target exactly behind the turtle is a turn of +π (counter-clockwise), the
  same answer from ``control.js`` (``wrapAngle``) and ``control.py``.
- :func:`turtlesim_normalize` wraps into ``[−π, π)``: what turtlesim's ``normalizeAngle`` does
  to the heading it publishes. Only the simulator uses it, so that its ``/turtle1/pose`` matches
  a real turtlesim's to the bit.
"""

from __future__ import annotations

import math


def wrap_angle(angle: float) -> float:
    """``angle`` wrapped into ``(−π, π]``: the convention of everything the project computes."""
    wrapped = math.remainder(angle, 2 * math.pi)
    return math.pi if wrapped <= -math.pi else wrapped


def turtlesim_normalize(angle: float) -> float:
    """``angle`` wrapped into ``[−π, π)``, as turtlesim normalises the pose it publishes;
    ``ValueError`` if it is not finite."""
    if not math.isfinite(angle):
        raise ValueError(f"angle must be finite, got {angle}")
    if abs(angle) > 1e9:
        # turtlesim's formula loses the range for huge angles (e.g. a teleport to θ = 1e308);
        # fmod is exact, so the result still lands inside it.
        angle = math.fmod(angle, 2.0 * math.pi)
    wrapped = angle - 2.0 * math.pi * math.floor((angle + math.pi) / (2.0 * math.pi))
    # Rounding can land exactly on π.
    return -math.pi if wrapped >= math.pi else wrapped
