"""A clock a test moves by hand, for the sans-I/O cores that take their time as a callable."""

from __future__ import annotations


class Clock:
    """Returns ``now``, which the test sets or advances."""

    def __init__(self, now: float = 0.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now
