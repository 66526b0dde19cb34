"""Pure figures of ``autopilot bench --onboard``: a robot that carries its camera, following the
walker of the simulated arena. No I/O, no clocks: the run collects the samples, these read them.

The truth is the robot's pose (its odometry, as the agent received it) against where the walker
stood at the same instant (:class:`Sighting`): the walker's true bearing from the camera's axis
(positive to the left, as a yaw) and its distance. From the first acquisition on (the walker
within :data:`ACQUIRED_DEG` of the axis for the first time):

- the bearing error is the walker's bearing, in degrees, while it is in the camera's view;
- the standoff error is its distance less the standoff, while in view;
- a reacquisition is the time from the walker leaving the view until it is back within
  :data:`ACQUIRED_DEG` of the axis (the search found it and the robot turned to it).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Final

from app.protocol.angles import wrap_angle
from app.tools.bench.stats import PoseSample

# "Back on the target": the walker within this many degrees of the camera's axis.
ACQUIRED_DEG: Final = 5.0


@dataclass(frozen=True)
class Sighting:
    """The walker as the robot's camera truly had it at time ``t``: its bearing (rad, positive
    to the left) and its distance (m) from the camera."""

    t: float
    bearing: float
    distance: float


@dataclass(frozen=True)
class Reacquisition:
    """The walker left the view at ``left_at`` on the ``side`` it left by, and was back within
    :data:`ACQUIRED_DEG` ``after_s`` later (None: not before the run ended)."""

    left_at: float
    side: str
    after_s: float | None


def sightings(
    poses: Sequence[PoseSample], walker_at: Callable[[float], tuple[float, float] | None]
) -> list[Sighting]:
    """The walker from each pose: ``walker_at(t)`` is where it stood at ``t`` (None: unknown
    then, and the pose is skipped)."""
    found = []
    for pose in poses:
        place = walker_at(pose.t)
        if place is None:
            continue
        dx, dy = place[0] - pose.x, place[1] - pose.y
        bearing = wrap_angle(math.atan2(dy, dx) - pose.theta)
        found.append(Sighting(pose.t, bearing, math.hypot(dx, dy)))
    return found


def in_view(sighting: Sighting, hfov: float) -> bool:
    """Whether the walker is within the camera's horizontal field of view ``hfov`` (rad)."""
    return abs(sighting.bearing) <= hfov / 2


def _acquired(sighting: Sighting) -> bool:
    return abs(math.degrees(sighting.bearing)) <= ACQUIRED_DEG


def after_acquisition(track: Sequence[Sighting]) -> list[Sighting]:
    """The sightings from the first one within :data:`ACQUIRED_DEG` of the axis on."""
    first = next((i for i, s in enumerate(track) if _acquired(s)), None)
    return [] if first is None else list(track[first:])


def bearing_errors_deg(track: Sequence[Sighting], hfov: float) -> list[float]:
    """The walker's bearing off the axis (degrees, unsigned) at every sighting in view after
    the first acquisition."""
    return [abs(math.degrees(s.bearing)) for s in after_acquisition(track) if in_view(s, hfov)]


def standoff_errors_m(track: Sequence[Sighting], hfov: float, standoff_m: float) -> list[float]:
    """The walker's distance less the standoff (m, signed: positive too far) at every sighting
    in view after the first acquisition."""
    return [s.distance - standoff_m for s in after_acquisition(track) if in_view(s, hfov)]


def min_distance_m(track: Sequence[Sighting]) -> float | None:
    """The walker's least distance from the camera over the whole track, in view or not (None
    for no sighting)."""
    return min((s.distance for s in track), default=None)


def reacquisitions(track: Sequence[Sighting], hfov: float) -> list[Reacquisition]:
    """Every time the walker left the view after the first acquisition, and how long it took
    to be back within :data:`ACQUIRED_DEG` of the axis."""
    found: list[Reacquisition] = []
    left: Sighting | None = None
    was_in_view = True
    for s in after_acquisition(track):
        seen = in_view(s, hfov)
        if left is None and was_in_view and not seen:
            left = s
        elif left is not None and _acquired(s):
            side = "left" if left.bearing > 0 else "right"
            found.append(Reacquisition(left.t, side, s.t - left.t))
            left = None
        was_in_view = seen
    if left is not None:
        found.append(Reacquisition(left.t, "left" if left.bearing > 0 else "right", None))
    return found
