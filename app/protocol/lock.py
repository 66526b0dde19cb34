"""Target lock: follow the object a person clicked, not the largest one. The rule, written once.

The relay owns the lock. A click (a point in frame pixels) picks among the boxes the operator sees:
the last snapshot's and, between full scans, the last full scan's that overlap none of them (the
candidates). The box that contains the click is picked, the smallest of several (a small box inside
a large one can only be meant by a click on it); else the box the click is nearest to, measured in
that box's own size -- the larger of the horizontal gap over the box's width and the vertical gap
over its height -- when that is at most ``near`` (a click on a face's hair or chin is meant for
that face). A click near no box searches the frame at full resolution in a square ``click_search``
of the frame's shorter side, centred on the click (a face the reduced-size scan is too coarse to
find is still one the operator sees), and the same pick among what that search finds is locked; a
target so found is followed at full resolution (the tracker's window around it, and when neither
that window nor a full scan finds it, the window around where it was last seen). A click where
nothing is found releases the lock. On each later snapshot the box that continues the locked track
is chosen among the boxes found (the tracker's window first): of the boxes of a similar size --
neither side more than ``max_scale`` times the locked box's, nor less than its ``1 / max_scale`` --
the one that overlaps it most; when none overlaps, the one whose centre is nearest to its centre,
within ``reach`` times its longer side. Ties go to the first box found. A locked target not seen
for ``search_after_s`` is searched for in the whole frame (any similar box, nearest first); not
seen for ``release_after_s``, the lock is released and the largest box is the target again --
unless the vehicle says it is turning to search for the target (its pose's ``search``: ``left``
or ``right``): then the lock holds, and lets go at the first snapshot after the search ended
(``timed_out``, or none). A target that comes back during the search is found by the whole-frame
search and locked again with no click. The target's look is the hue × saturation histogram
(``look_bins``, of OpenCV's 8-bit HSV, normalised) of its box on the first snapshot that followed
it after the lock; a box looks like it when their Bhattacharyya coefficient is at least
``min_likeness``. Once its look is known, a box of a similar size that overlaps the locked box
continues the track (the one overlapping most); else, wherever it is in the frame, the box of a
similar size that looks most like the target (a vehicle that turns moves the target across its
camera's frame faster than ``reach``; a face of the same size is not the same person). The
vehicle has turned away while it searches, and the target may come back nearer or farther: then
the box of any size that looks most like it is the target. Switching the operation releases the
lock.

Python applies the rule in :mod:`app.vision.lock`, the relay page in ``js/core/lock.js``, which gets
these numbers from its config (``config.protocol.lock``); tests/vision/test_lock.py and
e2e/test_lock_js.py check each against the rule (``TWO_FACES`` in tests/vision/lock_sequences.py),
and that the two agree on the same sequences.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LockRule:
    """The numbers of the target lock's rule (the defaults are the rule); times in seconds."""

    search_after_s: float = 1.0
    release_after_s: float = 3.0
    max_scale: float = 1.4
    reach: float = 1.0
    near: float = 0.5
    click_search: float = 0.6
    # The target's look: a hue × saturation histogram of its box with this many bins each way,
    # and the least likeness (Bhattacharyya coefficient, 1 the same) of a box taken for it while
    # the vehicle searches.
    look_bins: tuple[int, int] = (16, 16)
    min_likeness: float = 0.9
