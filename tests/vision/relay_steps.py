"""The relay's snapshots and clicks in Python, as its vision worker composes them.

``vision-worker.js`` runs each of the relay's snapshots through the tracker's window
(``core/tracking-window.js``), the operation and the target lock (``core/lock.js``); this does the
same with the Python twins (app/vision/window.py, reference.py, lock.py), so a test can follow a
scene the relay's way, or compare the worker's answers with these on the same pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from app.vision import lock, reference, window
from app.vision.reference import Detection, Rgba
from app.vision.spec import CascadeOperation

Box = lock.Box


@dataclass(frozen=True)
class Snapshot:
    """What one snapshot found and decided."""

    found: Detection
    scan: window.Scan
    chosen: Box | None  # the target's box: the locked one's track, or the largest
    target: tuple[float, float] | None  # the goal point
    full_scan: bool  # whether the whole (reduced) frame was scanned
    candidates: list[Box]  # the last full scan's boxes


@dataclass
class RelaySteps:
    """One relay's tracker and lock over a cascade operation's snapshots (default profile)."""

    op: CascadeOperation
    rule: lock.LockRule = field(default_factory=lock.LockRule)

    def __post_init__(self) -> None:
        self.tracker = window.Tracker(self.op.params.full_scan_every)
        self.lock = lock.TargetLock(self.rule)
        self.last: list[Box] = []
        self.last_full: list[Box] = []
        self.shown: Rgba | None = None

    def snapshot(self, rgba: Rgba, t: float, robot_searching: bool = False) -> Snapshot:
        """Analyse ``rgba`` at ``t`` seconds, as the worker's analyze with ``at``, ``track`` and
        ``robotSearching``."""
        query = self.lock.query(t, robot_searching)

        def look_of(box: Box) -> list[float]:
            return reference.look(rgba, box, self.rule.look_bins)

        choose = lock.chooser(query, self.rule, look_of)
        fine = query is not None and query.fine
        full: list[list[Box]] = []

        def detect(box: Box | None) -> Detection:
            found = reference.detect(
                self.op, rgba, around=box, full_resolution=fine and box is not None
            )
            if box is None:
                full.append(found.boxes)
            return found

        keep = query.box if query is not None and fine else None
        found, scan = window.step(self.tracker, detect, choose, keep)
        chosen = choose(found.boxes)
        target = found.target
        if query is not None:  # locked: the goal is the locked target's centre, or none
            target = None if chosen is None else lock.centre(chosen)
        if chosen is not None and self.lock.needs_look(query):
            self.lock.remember(look_of(chosen))
        self.lock.update(query, chosen, t, robot_searching)
        self.last, self.shown = found.boxes, rgba
        if full:
            self.last_full = full[0]
        return Snapshot(found, scan, chosen, target, bool(full), self.last_full)

    def click(self, x: float, y: float, t: float) -> Literal["picked", "searched"] | None:
        """A click at (x, y) at ``t`` on the last snapshot, as the worker's lockAt."""
        shown = self.shown
        assert shown is not None, "a click before any snapshot"
        height, width = shown.shape[:2]

        def search(region: Box) -> list[Box]:
            return reference.search(self.op, shown, region).boxes

        boxes = lock.lockable(self.last, self.last_full)
        how = lock.lock_at(self.lock, x, y, boxes, search, width, height, t)
        self.tracker.reset()
        return how
