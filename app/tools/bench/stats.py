"""Pure statistics over the samples a bench run collects: no I/O, no clocks, unit-tested alone."""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class Summary:
    """Distribution of one measured quantity."""

    n: int
    mean: float
    sd: float
    p50: float
    p95: float
    minimum: float
    maximum: float

    def as_dict(self) -> dict[str, float | int]:
        """Plain JSON-ready mapping."""
        return asdict(self)


def summarize(values: Sequence[float]) -> Summary | None:
    """Mean, sample standard deviation and percentiles; ``None`` when there is nothing to sum up.

    Percentiles interpolate linearly between order statistics (numpy's default), so p50 of an even
    count is the mean of the two middle values.
    """
    if not values:
        return None
    arr = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ValueError("samples must be finite")
    return Summary(
        n=int(arr.size),
        mean=float(arr.mean()),
        # ddof=1: the thesis's 196 ms is a sample standard deviation; one sample has none.
        sd=float(arr.std(ddof=1)) if arr.size > 1 else 0.0,
        p50=float(np.percentile(arr, 50)),
        p95=float(np.percentile(arr, 95)),
        minimum=float(arr.min()),
        maximum=float(arr.max()),
    )


def rate_per_s(timestamps: Iterable[float], start: float, end: float) -> float:
    """Events per second among ``timestamps`` falling in the window ``[start, end)``."""
    if end <= start:
        raise ValueError("empty window")
    count = sum(1 for t in timestamps if start <= t < end)
    return count / (end - start)


def glass_to_command_ms(
    frame_sent: Mapping[int, float], commands: Iterable[tuple[float, int]]
) -> list[float]:
    """Latency from sending frame *n* to the first command caused by the goal derived from it.

    ``frame_sent`` maps frame numbers to send times (s); ``commands`` are ``(time_s, frame)`` of
    each published Twist with the frame tag of the goal it was computed from. Both clocks are the
    same process's, so the difference is a true latency. Frames never acted upon contribute
    nothing: the goal rate is reported separately.
    """
    first_command: dict[int, float] = {}
    for t, frame in commands:
        if frame in frame_sent and (frame not in first_command or t < first_command[frame]):
            first_command[frame] = t
    return [
        (t - frame_sent[frame]) * 1000.0
        for frame, t in sorted(first_command.items())
        if t >= frame_sent[frame]
    ]


def wrap_angle(angle: float) -> float:
    """Angle wrapped into ``(-pi, pi]``."""
    wrapped = math.remainder(angle, 2 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


@dataclass(frozen=True)
class PoseSample:
    """The turtle's pose at time ``t`` (s)."""

    t: float
    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class TruthSample:
    """Where the synthetic face's target point truly was in frame pixels from time ``t`` on."""

    t: float
    x: float
    y: float
    w: int
    h: int


@dataclass(frozen=True)
class HeadingSample:
    """Turtle heading against the true direction to the target at one pose."""

    t: float
    heading: float
    truth: float
    error: float


# Below this distance the direction to the target is undefined (same threshold as the control law).
MIN_TARGET_DISTANCE_M = 0.05


def heading_track(
    poses: Sequence[PoseSample],
    truth: Sequence[TruthSample],
    to_terrain: Callable[[float, float, int, int], tuple[float, float]],
) -> list[HeadingSample]:
    """Pair each pose with the true target shown at that moment and the heading error to it.

    ``truth`` must be sorted by time; a pose before the first truth sample, or with the target
    on top of the turtle, is skipped. ``to_terrain`` is the control law's pixel-to-terrain map, so
    the truth is the direction a perfect detector plus that control law would steer to.
    """
    times = [s.t for s in truth]
    track: list[HeadingSample] = []
    for pose in poses:
        i = bisect.bisect_right(times, pose.t) - 1
        if i < 0:
            continue
        shown = truth[i]
        tx, ty = to_terrain(shown.x, shown.y, shown.w, shown.h)
        dx, dy = tx - pose.x, ty - pose.y
        if math.hypot(dx, dy) < MIN_TARGET_DISTANCE_M:
            continue
        direction = math.atan2(dy, dx)
        error = wrap_angle(pose.theta - direction)
        track.append(HeadingSample(pose.t, pose.theta, direction, error))
    return track


def heading_error_deg_median(track: Sequence[HeadingSample], after: float) -> float | None:
    """Median absolute heading error in degrees over samples at or after time ``after``."""
    errors = [abs(math.degrees(s.error)) for s in track if s.t >= after]
    return float(np.median(errors)) if errors else None


def growth_pct(start: float, end: float) -> float:
    """Relative growth from ``start`` to ``end`` in percent (negative when it shrank)."""
    if start <= 0:
        raise ValueError("start must be positive")
    return (end - start) / start * 100.0
