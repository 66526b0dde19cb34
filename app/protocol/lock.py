"""Target lock: the numbers of the rule (app/vision/lock.py and lock.js apply it).

A locked target not seen for ``search_after_s`` is searched for in the whole frame; not seen for
``release_after_s``, the lock is released (back to the largest). A box continues the track only
if neither side is more than ``max_scale`` times the locked box's, and, unless searching the
whole frame, its centre is within ``reach`` of the locked box's longer side from its centre.
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
