"""Detect, then track: the search window around the last target, and when to scan it all.

Once an operation has found its target, the next snapshots search only a window around the last
target box, in the same detection image (same reduction, same cascade, same parameters), and
only for sizes near the target's own, so the cascade runs over a fraction of the pixels and of
the scales. The whole frame is scanned again every ``full_scan_every`` snapshots, and at once,
on the same snapshot, when the window finds nothing.

This module is the Python side of ``app/static/js/core/tracking-window.js``; both compute the same
window from the same doubles and take the same decisions, so ``autopilot parity`` can compare the
windowed path box for box. Pure numpy/OpenCV, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal, Protocol, TypeVar

from cv2.typing import MatLike

Box = tuple[int, int, int, int]
Size = tuple[int, int]
Scan = Literal["full", "window"]


def search_region(around: Box, factor: float, width: int, height: int, margin: float) -> Box | None:
    """The window ``(x, y, w, h)`` in detection-image pixels, or None when it is empty.

    ``around`` is a full-frame box, ``factor`` scales detection-image pixels to full-frame
    pixels, ``width`` × ``height`` is the detection image; the box is grown by ``margin`` of its
    size on each side and clipped to the image. Floor and ceil are written out so JavaScript
    computes the same integers from the same doubles.
    """
    x, y, w, h = (v / factor for v in around)
    x0 = max(0, math.floor(x - w * margin))
    y0 = max(0, math.floor(y - h * margin))
    x1 = min(width, math.ceil(x + w + w * margin))
    y1 = min(height, math.ceil(y + h + h * margin))
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1 - x0, y1 - y0


def search_sizes(
    around: Box, factor: float, ratio: float, min_size: Size, max_size: Size
) -> tuple[Size, Size]:
    """The smallest and largest object sizes a window search looks for, in detection-image pixels.

    From the last target's sides: the shorter divided by ``ratio`` and the longer multiplied by
    it, within the operation's own ``min_size`` and ``max_size`` (``(0, 0)``: no limit). A tracked
    target changes size little from one snapshot to the next, and the small scales are the
    cascade's costly ones (the most positions); a target that grew or shrank past the range
    leaves the window empty, and the full scan that follows finds it on the same snapshot.
    """
    shortest = math.floor(min(around[2], around[3]) / factor / ratio)
    longest = math.ceil(max(around[2], around[3]) / factor * ratio)
    smallest = (max(min_size[0], shortest), max(min_size[1], shortest))
    if max_size[0] == 0 or max_size[1] == 0:
        return smallest, (longest, longest)
    return smallest, (min(max_size[0], longest), min(max_size[1], longest))


def source_rect(region: Box, width: int, height: int, size: Size) -> tuple[Box, Box] | None:
    """Where to reduce only the window: ``(reduced, source)``, the window grown to the
    reduction's grid (detection-image pixels) and the part of the ``width`` × ``height`` frame
    that reduces to exactly it; None when the grid is not exact in doubles (then the whole frame
    is reduced and the window cropped from it, as before).

    INTER_AREA makes each detection pixel a weighted mean of the frame pixels under it, with
    weights that repeat every ``period`` detection pixels (``period`` × scale frame pixels, a
    whole number). A part of the frame that starts and ends on that grid reduces to exactly the
    pixels the whole frame's reduction has there, for a fraction of the work. OpenCV computes the
    weights from index × scale in doubles, exact on both sides only when the scale is a binary
    fraction: a power-of-two ``period``.
    """
    x = _on_grid(region[0], region[0] + region[2], width, size[0])
    y = _on_grid(region[1], region[1] + region[3], height, size[1])
    if x is None or y is None:
        return None
    (x0, x1, sx0, sx1), (y0, y1, sy0, sy1) = x, y
    return (x0, y0, x1 - x0, y1 - y0), (sx0, sy0, sx1 - sx0, sy1 - sy0)


def _on_grid(start: int, end: int, frame: int, reduced: int) -> tuple[int, int, int, int] | None:
    """One axis of :func:`source_rect`: ``[start, end)`` of the detection image grown to the
    grid, and the frame pixels under it."""
    common = math.gcd(frame, reduced)
    period, step = reduced // common, frame // common
    if period & (period - 1):
        return None
    lo = start // period * period
    hi = min(reduced, -(-end // period) * period)
    return lo, hi, lo // period * step, hi // period * step


def crop(image: MatLike, region: Box) -> MatLike:
    """The part of ``image`` inside ``region`` (a view, no copy), as OpenCV.js's ``roi``."""
    x, y, w, h = region
    return image[y : y + h, x : x + w]


def largest(boxes: Sequence[Box]) -> Box | None:
    """The largest box, the first of equal areas (the one whose centre is the target)."""
    best: Box | None = None
    for box in boxes:
        if best is None or box[2] * box[3] > best[2] * best[3]:
            best = box
    return best


class Found(Protocol):
    """What a detection returns: boxes in full-frame pixels."""

    @property
    def boxes(self) -> list[Box]: ...


D = TypeVar("D", bound=Found)


@dataclass
class Tracker:
    """When to search a window and when the whole frame; one per operation and profile.

    ``full_scan_every`` = 1 scans every snapshot in full (tracking off).
    """

    full_scan_every: int
    last: Box | None = None  # full-frame box of the last target
    windowed: int = 0  # snapshots searched in a window since the last full scan

    def window(self) -> Box | None:
        """The box to search around on the next snapshot, or None for a full scan."""
        if self.last is None or self.windowed >= self.full_scan_every - 1:
            return None
        return self.last

    def record(self, box: Box | None, scan: Scan) -> None:
        """Remember the target box a snapshot's search chose (None: nothing chosen)."""
        self.last = box
        self.windowed = self.windowed + 1 if scan == "window" else 0

    def reset(self) -> None:
        """Forget the target: the next snapshot is a full scan."""
        self.last = None
        self.windowed = 0


Choose = Callable[[Sequence[Box]], Box | None]


def step(
    tracker: Tracker,
    detect: Callable[[Box | None], D],
    choose: Choose = largest,
    keep: Box | None = None,
) -> tuple[D, Scan]:
    """One snapshot: search the window if there is one, the whole frame when it finds nothing.

    ``detect(around)`` runs the operation around a full-frame box, or on the whole frame when
    ``around`` is None. ``choose`` picks the target among the boxes found: the largest, or the
    locked target's box (``app/vision/lock.py``); a window where it picks none is a miss.
    ``keep``: where a target that the whole-frame scan cannot find was last seen (a lock found
    at full resolution): when the full scan does not find it either, the window around ``keep``
    is searched last, and a target found there is the snapshot's (scan ``"window"``).
    """
    around = tracker.window()
    if around is not None:
        found = detect(around)
        box = choose(found.boxes)
        if box is not None:
            tracker.record(box, "window")
            return found, "window"
    found = detect(None)
    box = choose(found.boxes)
    # A full scan ran, found or not: the next one is due in full_scan_every snapshots.
    tracker.record(box, "full")
    if box is None and keep is not None and keep != around:
        kept = detect(keep)
        box = choose(kept.boxes)
        if box is not None:
            tracker.last = box
            return kept, "window"
    return found, "full"
