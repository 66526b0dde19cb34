"""Target lock in Python: the rule of :mod:`app.protocol.lock` (written there, with its numbers).

The Python twin of the relay page's ``js/core/lock.js``: both take the same decisions from the same
doubles, checked on the same sequences (``e2e/test_lock_js.py``). Pure, no I/O, time given.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Literal

from app.protocol.channels import LockState, SearchStatus
from app.protocol.lock import LockRule
from app.vision.window import Box, Choose, largest


def contains(box: Box, x: float, y: float) -> bool:
    """Whether pixel (x, y) is inside ``box``, edges included."""
    bx, by, bw, bh = box
    return bx <= x <= bx + bw and by <= y <= by + bh


def gap(box: Box, x: float, y: float) -> float:
    """How far pixel (x, y) is from ``box`` in the box's own size: the larger of the horizontal
    gap over its width and the vertical gap over its height (0 inside, edges included)."""
    bx, by, bw, bh = box
    dx = max(bx - x, 0.0, x - (bx + bw))
    dy = max(by - y, 0.0, y - (by + bh))
    return max(dx / bw, dy / bh)


def centre(box: Box) -> tuple[float, float]:
    """The centre of ``box``."""
    return box[0] + box[2] / 2, box[1] + box[3] / 2


def pick(x: float, y: float, boxes: Sequence[Box], near: float) -> Box | None:
    """The box clicked at (x, y): of the boxes containing it the smallest (the first of equal
    areas), since a small box inside a large one can only be meant by a click on it; else the
    box it is nearest to in that box's own size (:func:`gap`, the first of equal gaps), when at
    most ``near``."""
    best: Box | None = None
    for box in boxes:
        if contains(box, x, y) and (best is None or box[2] * box[3] < best[2] * best[3]):
            best = box
    if best is not None:
        return best
    best_gap = near
    for box in boxes:
        g = gap(box, x, y)
        if g <= best_gap and (best is None or g < best_gap):
            best, best_gap = box, g
    return best


def lockable(boxes: Sequence[Box], candidates: Sequence[Box]) -> list[Box]:
    """The boxes the operator sees and may click: a snapshot's ``boxes``, then those of the
    last full scan's ``candidates`` that overlap none of them (the others are the same targets,
    seen earlier)."""
    return [*boxes, *(c for c in candidates if all(overlap(c, b) == 0 for b in boxes))]


def click_window(x: float, y: float, width: int, height: int, share: float) -> Box | None:
    """Where a click near no box is searched at full resolution: a square ``share`` of the
    ``width`` × ``height`` frame's shorter side centred on (x, y), moved inside the frame; None
    for a click outside the frame."""
    if not (0 <= x <= width and 0 <= y <= height):
        return None
    side = math.floor(share * min(width, height))
    x0 = min(max(0, math.floor(x - side / 2)), width - side)
    y0 = min(max(0, math.floor(y - side / 2)), height - side)
    return x0, y0, side, side


def overlap(a: Box, b: Box) -> float:
    """Intersection over union of two boxes."""
    w = min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0])
    h = min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1])
    if w <= 0 or h <= 0:
        return 0.0
    inter = w * h
    return inter / (a[2] * a[3] + b[2] * b[3] - inter)


def similar(box: Box, locked: Box, max_scale: float) -> bool:
    """Neither side of ``box`` is more than ``max_scale`` times the locked box's, or less than
    its ``1 / max_scale``."""
    return all(box[i] <= max_scale * locked[i] and locked[i] <= max_scale * box[i] for i in (2, 3))


def associate(locked: Box, boxes: Sequence[Box], anywhere: bool, rule: LockRule) -> Box | None:
    """The box among ``boxes`` that continues the track of ``locked``, or None.

    Of the boxes of a similar size: the one that overlaps it most; when none overlaps, the one
    whose centre is nearest to its centre, within ``rule.reach`` times its longer side unless
    ``anywhere`` (the whole-frame search). Ties go to the first box, as in lock.js.
    """
    candidates = [b for b in boxes if similar(b, locked, rule.max_scale)]
    best: Box | None = None
    best_overlap = 0.0
    for box in candidates:
        iou = overlap(box, locked)
        if iou > best_overlap:
            best, best_overlap = box, iou
    if best is not None:
        return best
    lx, ly = centre(locked)
    reach = rule.reach * max(locked[2], locked[3])
    limit = math.inf if anywhere else reach * reach
    best_d2 = math.inf
    for box in candidates:
        cx, cy = centre(box)
        dx, dy = cx - lx, cy - ly
        d2 = dx * dx + dy * dy
        if d2 <= limit and (best is None or d2 < best_d2):
            best, best_d2 = box, d2
    return best


Look = Sequence[float]


def look_rect(box: Box, width: int, height: int) -> Box:
    """The pixels a look is taken from: ``box`` grown to whole pixels and clipped to the
    ``width`` × ``height`` frame, as (x, y, w, h) (empty when the box is outside it)."""
    x, y, w, h = box
    x0 = min(max(0, math.floor(x)), width)
    y0 = min(max(0, math.floor(y)), height)
    x1 = min(max(x0, math.ceil(x + w)), width)
    y1 = min(max(y0, math.ceil(y + h)), height)
    return x0, y0, x1 - x0, y1 - y0


def likeness(a: Look, b: Look) -> float:
    """How alike two looks (normalised histograms) are: their Bhattacharyya coefficient, 1 for
    the same, 0 for nothing in common."""
    return sum(math.sqrt(x * y) for x, y in zip(a, b, strict=True))


def recognise(boxes: Sequence[Box], alike: Callable[[Box], float], rule: LockRule) -> Box | None:
    """The box of any size most like the target (``alike(box)``, its likeness), when at least
    ``rule.min_likeness`` alike; the first of equal likeness."""
    best: Box | None = None
    best_likeness = rule.min_likeness
    for box in boxes:
        value = alike(box)
        if value >= best_likeness and (best is None or value > best_likeness):
            best, best_likeness = box, value
    return best


@dataclass(frozen=True)
class Query:
    """What one snapshot is asked to follow: the locked box, whether to accept it anywhere in
    the frame, the lock's ``epoch`` then (an answer to an older lock is not news), whether
    the target was found at full resolution (``fine``: it is followed at full resolution), the
    target's look (``look``: None until known), and whether a box of any size may be it
    (``any_size``: while the vehicle searches)."""

    box: Box
    anywhere: bool
    epoch: int
    fine: bool = False
    look: Look | None = None
    any_size: bool = False


def chooser(
    query: Query | None, rule: LockRule, look_of: Callable[[Box], Look] | None = None
) -> Choose:
    """The rule that picks the target among a snapshot's boxes (``window.step``): the locked
    target's track, or the largest box when nothing is locked. When the query gives the
    target's look and ``look_of(box)`` each box's, a box of a similar size that overlaps the
    locked one continues its track (the one overlapping most); else the box that looks most
    like the target (:func:`recognise`) among those of a similar size, of any size while the
    vehicle searches, wherever it is in the frame."""
    if query is None:
        return largest
    look = query.look
    if look is None or look_of is None:
        return lambda boxes: associate(query.box, boxes, query.anywhere, rule)

    def alike(box: Box) -> float:
        return likeness(look_of(box), look)

    def choose(boxes: Sequence[Box]) -> Box | None:
        similar_boxes = [b for b in boxes if similar(b, query.box, rule.max_scale)]
        overlapping = [b for b in similar_boxes if overlap(b, query.box) > 0]
        if overlapping:
            return associate(query.box, overlapping, False, rule)
        return recognise(boxes if query.any_size else similar_boxes, alike, rule)

    return choose


@dataclass
class TargetLock:
    """The relay's lock on one target; times in seconds on any monotonic clock."""

    rule: LockRule = field(default_factory=LockRule)
    box: Box | None = None  # the locked target's box when last seen
    seen_at: float = 0.0
    state: LockState = "none"
    epoch: int = 0  # bumped by every lock and release
    fine: bool = False  # found by a full-resolution search: followed at full resolution
    look: Look | None = None  # the target's look, from the first snapshot that followed it

    def lock(self, x: float, y: float, boxes: Sequence[Box], now: float) -> bool:
        """A click at (x, y) on a snapshot that found ``boxes``: lock the box clicked (or near
        the click), or release when there is none. True when locked. A click on the target
        locked already keeps it followed as it was (at full resolution or not)."""
        box = pick(x, y, boxes, self.rule.near)
        if box is None:
            self.release()
            return False
        same = self.box is not None and overlap(box, self.box) > 0
        self.hold(box, now, fine=self.fine and same)
        return True

    def hold(self, box: Box, now: float, fine: bool = False) -> None:
        """Lock on ``box``, seen at ``now``; ``fine``: found at full resolution."""
        self.box, self.seen_at, self.state, self.fine = box, now, "locked", fine
        self.look = None
        self.epoch += 1

    def release(self) -> None:
        """Back to the default choice (the largest box)."""
        self.box, self.state, self.fine, self.look = None, "none", False, None
        self.epoch += 1

    def query(self, now: float, robot_searching: bool = False) -> Query | None:
        """What the next snapshot follows, or None for the default choice: once the target's
        look is known, by its look (:func:`chooser`), of any size while the vehicle searches
        (``robot_searching``)."""
        if self.box is None:
            return None
        anywhere = now - self.seen_at > self.rule.search_after_s
        return Query(self.box, anywhere, self.epoch, self.fine, self.look, robot_searching)

    def needs_look(self, query: Query | None) -> bool:
        """Whether the box the snapshot asked with ``query`` chose is to give the target's
        look: the first one after a lock."""
        return query is not None and query.epoch == self.epoch and self.look is None

    def remember(self, look: Look) -> None:
        """The target's look (:meth:`needs_look`)."""
        self.look = look

    def update(
        self,
        query: Query | None,
        chosen: Box | None,
        now: float,
        robot_searching: bool = False,
    ) -> LockState | None:
        """The outcome of the snapshot asked with ``query``: the box chosen, or None when the
        target was not found; ``robot_searching``: the vehicle says it is turning to search for
        the target (its pose's ``search``), and the lock holds until that search ends. Returns
        the new state when it changed."""
        if query is None or query.epoch != self.epoch:
            return None
        before = self.state
        if chosen is not None:
            self.box, self.seen_at, self.state = chosen, now, "locked"
        elif now - self.seen_at > self.rule.release_after_s and not robot_searching:
            self.release()
        elif now - self.seen_at > self.rule.search_after_s:
            self.state = "searching"
        else:
            self.state = "lost"
        return self.state if self.state != before else None


def robot_searching(search: SearchStatus | None) -> bool:
    """Whether a vehicle whose pose says ``search`` is turning to search for its lost target
    (a search that ran out, or none, is not). lock.js ``robotSearching`` is its twin."""
    return search is not None and search != "timed_out"


Search = Callable[[Box], Sequence[Box]]


def lock_at(
    target: TargetLock,
    x: float,
    y: float,
    boxes: Sequence[Box],
    search: Search | None,
    width: int,
    height: int,
    now: float,
) -> Literal["picked", "searched"] | None:
    """A click at (x, y) of a ``width`` × ``height`` frame on which the operator saw
    ``boxes`` (:func:`lockable`): lock the box picked there; else, when the operation can,
    ``search`` the click's window (:func:`click_window`) at full resolution and lock the box
    picked among what it finds (a ``fine`` lock); else release. Returns how it locked, or None
    when it released. The relay's worker does the same (lock.js ``lockAt``)."""
    if target.lock(x, y, boxes, now):
        return "picked"
    window = click_window(x, y, width, height, target.rule.click_search)
    if search is None or window is None:
        return None
    found = pick(x, y, search(window), target.rule.near)
    if found is None:
        return None
    target.hold(found, now, fine=True)
    return "searched"
