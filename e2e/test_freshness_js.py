"""The vehicle page's latest-wins rule (freshness.js) agrees with the agent's (freshness.py)."""

from __future__ import annotations

import random
from collections.abc import Iterator
from dataclasses import asdict

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from e2e.helpers import module_page
from vehicle_agent.freshness import FreshnessRule, GoalGate

pytestmark = [pytest.mark.browser]


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/freshness") as opened:
        yield opened


def _arrivals(rng: random.Random) -> list[tuple[int, float, float]]:
    """Goals at 20/s over 20 s through a path with jitter, reordering, a 3 s outage whose
    goals land in one burst, and a path that gets 0.8 s slower for good; (seq, sent ms, now s)."""
    arrivals = []
    for seq in range(400):
        sent = seq * 0.05
        now = sent + 0.03 + rng.uniform(0, 0.1)
        if 5.0 <= sent < 8.0:
            now = 8.2
        if sent >= 12.0:
            now += 0.8
        arrivals.append((seq, sent * 1000 - 777_000, now))
    arrivals.sort(key=lambda a: a[2])
    return arrivals


def test_the_page_and_the_agent_judge_every_goal_alike(page: Page) -> None:
    rule = FreshnessRule()
    arrivals = _arrivals(random.Random(7))
    gate = GoalGate(rule)
    python = [gate.admit(seq, sent, now) for seq, sent, now in arrivals]
    js = page.evaluate(
        """([rule, arrivals]) => {
             const gate = new freshness.GoalGate({maxAgeS: rule.max_age_s, windowS: rule.window_s});
             return arrivals.map(([seq, sent, now]) => gate.admit(seq, sent, now));
           }""",
        [asdict(rule), arrivals],
    )
    assert js == python
    # The scenario exercises every verdict, so agreement means something.
    assert {"fresh", "old", "stale"} <= set(python)
