"""Latest-wins for goals on the lossy channel (docs/architecture.md, "Lossy links").

Goals ride an unordered channel that never retransmits, so they may arrive out of order, or late
in a burst after an outage. A goal is *state*: only the newest matters. :class:`GoalGate` admits a
goal when its ``seq`` is newer than every goal admitted before, and when it is not stale.

Staleness without synchronised clocks: a goal carries its sender's clock ``t`` (ms). For each goal
``offset = receive time - t`` is the one-way delay plus the unknown clock offset; the smallest
offset over the last ``window_s`` stands for the path's base delay, and a goal whose offset
exceeds that base by more than ``max_age_s`` waited that much longer than the quickest recent
goal on the way: it is stale. The window lets the base follow a path that got slower for good (a
new route after an ICE restart) instead of refusing everything forever.

Goals from the future are refused (``future``) before anything else: a ``seq`` beyond what the
link can have reached since the last goal applied (``GOAL_SEQ_BURST`` plus ``GOAL_SEQ_RATE_HZ``
per second), or a ``t`` more than ``GOAL_MAX_CLOCK_SKEW_S`` ahead of this side's wall clock. Either
would otherwise hold back every real goal after it: a huge ``seq`` makes them all ``old``, an early
``t`` makes them all look late. A refused goal changes nothing in the gate. The page's
``freshness.js`` applies the same rule; both run the shared sequences of
``tests/vehicle_agent/core/freshness_sequences.py``.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from app.protocol.channels import (
    GOAL_AGE_WINDOW_S,
    GOAL_MAX_AGE_S,
    GOAL_MAX_CLOCK_SKEW_S,
    GOAL_SEQ_BURST,
    GOAL_SEQ_RATE_HZ,
)

Verdict = Literal["fresh", "old", "stale", "future"]


@dataclass(frozen=True)
class FreshnessRule:
    """The numbers of the rule (defaults: ``app.protocol.channels``, which pages get too)."""

    max_age_s: float = GOAL_MAX_AGE_S
    window_s: float = GOAL_AGE_WINDOW_S
    max_skew_s: float = GOAL_MAX_CLOCK_SKEW_S
    seq_rate_hz: float = GOAL_SEQ_RATE_HZ
    seq_burst: int = GOAL_SEQ_BURST


def wall_clock_ms() -> float:
    """This machine's wall clock, Unix milliseconds (what a relay stamps goals with)."""
    return time.time() * 1000


class GoalGate:
    """Decides per goal: ``fresh`` (apply it), ``old`` (seq not newer), ``stale`` (too late) or
    ``future`` (numbered or stamped beyond what the link can have reached).

    One gate per link: a new relay connection starts its ``seq`` again, so :meth:`reset` it.
    ``wall_clock`` is this side's wall clock in Unix ms (injected by tests).
    """

    def __init__(
        self,
        rule: FreshnessRule = FreshnessRule(),
        wall_clock: Callable[[], float] = wall_clock_ms,
    ) -> None:
        self.rule = rule
        self.wall_clock = wall_clock
        self.last_seq: int | None = None
        self._last_at: float | None = None  # when the last goal was applied (receiver's clock)
        self._offsets: deque[tuple[float, float]] = deque()  # (received at, offset), both s

    def reset(self) -> None:
        """Forget everything (a new link)."""
        self.last_seq = None
        self._last_at = None
        self._offsets.clear()

    def admit(self, seq: int, sent_ms: float, now_s: float) -> Verdict:
        """Judge a goal with sequence ``seq`` sent at ``sent_ms`` (sender's clock) received at
        ``now_s`` (receiver's clock, seconds)."""
        if self._beyond_reach(seq, now_s) or sent_ms > self._latest_believable_ms():
            return "future"
        offset = now_s - sent_ms / 1000
        # Keep a monotone deque: its head is the window's minimum offset.
        while self._offsets and self._offsets[0][0] < now_s - self.rule.window_s:
            self._offsets.popleft()
        while self._offsets and self._offsets[-1][1] >= offset:
            self._offsets.pop()
        self._offsets.append((now_s, offset))
        if self.last_seq is not None and seq <= self.last_seq:
            return "old"
        if offset - self._offsets[0][1] > self.rule.max_age_s:
            return "stale"
        self.last_seq = seq
        self._last_at = now_s
        return "fresh"

    def _beyond_reach(self, seq: int, now_s: float) -> bool:
        if self.last_seq is None or self._last_at is None:
            return False
        reach = self.rule.seq_burst + self.rule.seq_rate_hz * max(now_s - self._last_at, 0.0)
        return seq - self.last_seq > reach

    def _latest_believable_ms(self) -> float:
        return self.wall_clock() + self.rule.max_skew_s * 1000
