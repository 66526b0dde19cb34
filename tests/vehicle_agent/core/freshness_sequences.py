"""Arrivals of goals at the latest-wins gate, run by ``freshness.py`` (tests/vehicle_agent/
test_freshness.py) and ``freshness.js`` (e2e/test_freshness_js.py): both must give every goal
the same verdict. Each arrival is ``(seq, sent ms, received s)``; the receiver's wall clock
stands at :data:`WALL_MS` throughout (the gates are given it)."""

from __future__ import annotations

import random

from app.protocol.channels import GOAL_MAX_CLOCK_SKEW_S

Arrival = tuple[int, float, float]

# The receiver's wall clock (Unix ms) while the sequences run.
WALL_MS = 1_800_000_000_000.0
# The relay's clock runs this far behind the receiver's: the gate never needs them to agree
# closer than the skew it allows.
RELAY_BEHIND_MS = 777_000.0


def lossy_path(rng: random.Random) -> list[Arrival]:
    """Goals at 20/s over 20 s through a path with jitter, reordering, a 3 s outage whose goals
    land in one burst, and a path that gets 0.8 s slower for good."""
    arrivals = []
    for seq in range(1, 401):
        sent = seq * 0.05
        now = sent + 0.03 + rng.uniform(0, 0.1)
        if 5.0 <= sent < 8.0:
            now = 8.2
        if sent >= 12.0:
            now += 0.8
        arrivals.append((seq, WALL_MS - RELAY_BEHIND_MS + sent * 1000, now))
    arrivals.sort(key=lambda a: a[2])
    return arrivals


def from_the_future() -> list[Arrival]:
    """Goals at 20/s among which a buggy relay slips seqs far ahead (2**40, 2**52, one past the
    reach) and stamps far ahead (an hour, just past the skew)."""
    arrivals: list[Arrival] = []
    skew_ms = GOAL_MAX_CLOCK_SKEW_S * 1000
    for seq in range(1, 201):
        now = seq * 0.05
        sent = WALL_MS - RELAY_BEHIND_MS + now * 1000 - 20
        arrivals.append((seq, sent, now))
        if seq in (20, 60):
            arrivals.append((2**40 if seq == 20 else 2**52, sent, now + 0.001))
        if seq == 80:
            arrivals.append((seq + 1, WALL_MS + 3_600_000, now + 0.001))
        if seq == 100:
            arrivals.append((seq + 1, WALL_MS + skew_ms + 1, now + 0.001))
        if seq == 160:
            arrivals.append((seq + 121, sent, now + 0.001))  # one past the reach
    return arrivals


SEQUENCES = {"lossy path": lossy_path(random.Random(7)), "from the future": from_the_future()}
