"""The vehicle page's latest-wins rule (freshness.js) agrees with the agent's (freshness.py)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, Page

from app.protocol.page import page_protocol, to_json
from app.server.serve import RunningServer
from e2e.helpers import module_page
from tests.vehicle_agent.core.freshness_sequences import SEQUENCES, WALL_MS
from vehicle_agent.core.freshness import FreshnessRule, GoalGate

pytestmark = [pytest.mark.browser]


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/freshness") as opened:
        yield opened


@pytest.mark.parametrize("name", SEQUENCES)
def test_the_page_and_the_agent_judge_every_goal_alike(page: Page, name: str) -> None:
    rule = FreshnessRule()
    arrivals = SEQUENCES[name]
    gate = GoalGate(rule, wall_clock=lambda: WALL_MS)
    python = [gate.admit(seq, sent, now) for seq, sent, now in arrivals]
    js = page.evaluate(
        """([rule, wallMs, arrivals]) => {
             const gate = new freshness.GoalGate(rule, () => wallMs);
             return arrivals.map(([seq, sent, now]) => gate.admit(seq, sent, now));
           }""",
        [to_json(page_protocol().goal_freshness), WALL_MS, arrivals],
    )
    assert js == python
    # The page gets the agent's rule: the same numbers, from one place.
    assert to_json(page_protocol().goal_freshness) == to_json(rule)
    # Each sequence exercises the verdicts it is about, so agreement means something.
    assert ({"future"} if name == "from the future" else {"fresh", "old", "stale"}) <= set(python)
