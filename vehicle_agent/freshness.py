"""Latest-wins for goals on the lossy channel (docs/architecture.md, "Lossy links").

Goals ride an unordered channel that never retransmits, so they may arrive out of order, or late
in a burst after an outage. A goal is *state*: only the newest matters. :class:`GoalGate` admits a
goal when its ``seq`` is newer than every goal admitted before, and when it is not stale.

Staleness without synchronised clocks: a goal carries its sender's clock ``t`` (ms). For each goal
``offset = receive time - t`` is the one-way delay plus the unknown clock offset; the smallest
offset over the last ``window_s`` stands for the path's base delay, and a goal whose offset
exceeds that base by more than ``max_age_s`` waited that much longer than the quickest recent
goal on the way: it is stale. The window lets the base follow a path that got slower for good (a
new route after an ICE restart) instead of refusing everything forever. The page's
``freshness.js`` applies the same rule.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Literal

from app.protocol.channels import GOAL_AGE_WINDOW_S, GOAL_MAX_AGE_S

Verdict = Literal["fresh", "old", "stale"]


@dataclass(frozen=True)
class FreshnessRule:
    """The numbers of the rule (defaults: ``app.protocol.channels``, which pages get too)."""

    max_age_s: float = GOAL_MAX_AGE_S
    window_s: float = GOAL_AGE_WINDOW_S


class GoalGate:
    """Decides per goal: ``fresh`` (apply it), ``old`` (seq not newer) or ``stale`` (too late).

    One gate per link: a new relay connection starts its ``seq`` again, so :meth:`reset` it.
    """

    def __init__(self, rule: FreshnessRule = FreshnessRule()) -> None:
        self.rule = rule
        self.last_seq: int | None = None
        self._offsets: deque[tuple[float, float]] = deque()  # (received at, offset), both s

    def reset(self) -> None:
        """Forget everything (a new link)."""
        self.last_seq = None
        self._offsets.clear()

    def admit(self, seq: int, sent_ms: float, now_s: float) -> Verdict:
        """Judge a goal with sequence ``seq`` sent at ``sent_ms`` (sender's clock) received at
        ``now_s`` (receiver's clock, seconds)."""
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
        return "fresh"
