"""Target lock: follow the object a person clicked, not the largest one. The rule, written once.

The relay owns the lock. A click (a point in frame pixels) locks the box that contains it, the
smallest of several (a small box inside a large one can only be meant by a click on it); a click
on no box releases the lock. On each later snapshot the box that continues the locked track is
chosen among the boxes found (the tracker's window first): of the boxes of a similar size --
neither side more than ``max_scale`` times the locked box's, nor less than its ``1 / max_scale``
-- the one that overlaps it most; when none overlaps, the one whose centre is nearest to its
centre, within ``reach`` times its longer side. Ties go to the first box found. A locked target
not seen for ``search_after_s`` is searched for in the whole frame (any similar box, nearest
first); not seen for ``release_after_s``, the lock is released and the largest box is the target
again. Switching the operation releases the lock.

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
