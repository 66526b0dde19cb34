"""link-health.js's figures from getStats() reports: loss over the period, frames per second,
round trip, the pair's most relayed candidate type, and the warnings at the thresholds of
app/protocol/link_health.py (which reach the page as ``PROTOCOL.health``)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.protocol.link_health import HEALTH
from app.protocol.page import page_protocol, to_json
from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.browser]

# Through the meter, the public way in: a stand-in connection whose getStats() gives the
# reports in turn, read once a report.
FIGURES_JS = """async ([previous, now]) => {
  const reports = [previous, now]
    .filter((entries) => entries !== null)
    .map((entries) => new Map(entries.map((s) => [s.id, s])));
  const meter = new window['link-health'].LinkMeter({ getStats: async () => reports.shift() });
  let figures = null;
  while (reports.length > 0) figures = await meter.read();
  return figures;
}"""
WARNINGS_JS = """([figures, limits]) => window['link-health'].warnings('link', figures, limits)"""


def report(t_ms: float, received: int, lost: int, frames: int, local: str, remote: str) -> list:
    return [
        {"id": "T", "type": "transport", "selectedCandidatePairId": "P"},
        {
            "id": "P",
            "type": "candidate-pair",
            "localCandidateId": "L",
            "remoteCandidateId": "R",
            "currentRoundTripTime": 0.042,
            "nominated": True,
            "state": "succeeded",
        },
        {"id": "L", "type": "local-candidate", "candidateType": local},
        {"id": "R", "type": "remote-candidate", "candidateType": remote},
        {
            "id": "V",
            "type": "inbound-rtp",
            "kind": "video",
            "timestamp": t_ms,
            "packetsReceived": received,
            "packetsLost": lost,
            "framesDecoded": frames,
            "frameWidth": 640,
            "frameHeight": 480,
        },
    ]


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "net/link-health") as opened:
        yield opened


def figures(page: Page, previous: list | None, now: list) -> dict[str, Any]:
    result: dict[str, Any] = page.evaluate(FIGURES_JS, [previous, now])
    return result


def test_figures_over_one_period(page: Page) -> None:
    first = report(1000, 900, 10, 100, "host", "host")
    # No rates from one report, but what it says at once.
    assert figures(page, None, first) == {
        "rttMs": 42,
        "lossPct": None,
        "fps": None,
        "width": 640,
        "height": 480,
        "candidate": "host",
    }
    # Over the next second: 90 packets came, 10 more were lost (10 %), 30 frames decoded.
    got = figures(page, first, report(2000, 990, 20, 130, "host", "host"))
    assert got["lossPct"] == pytest.approx(10.0) and got["fps"] == pytest.approx(30.0)


@pytest.mark.parametrize(
    ("local", "remote", "pair"),
    [("host", "host", "host"), ("host", "srflx", "srflx"), ("relay", "host", "relay")],
)
def test_the_pair_is_as_relayed_as_its_most_relayed_end(
    page: Page, local: str, remote: str, pair: str
) -> None:
    assert figures(page, None, report(0, 0, 0, 0, local, remote))["candidate"] == pair


def test_warnings_at_the_protocol_s_thresholds(page: Page) -> None:
    limits = to_json(page_protocol().health)
    assert limits == {
        "periodS": HEALTH.period_s,
        "maxLossPct": HEALTH.max_loss_pct,
        "maxRttMs": HEALTH.max_rtt_ms,
    }
    calm = {"lossPct": HEALTH.max_loss_pct, "rttMs": HEALTH.max_rtt_ms}
    assert page.evaluate(WARNINGS_JS, [calm, limits]) == []
    bad = {"lossPct": HEALTH.max_loss_pct + 1, "rttMs": HEALTH.max_rtt_ms + 1}
    found = page.evaluate(WARNINGS_JS, [bad, limits])
    assert len(found) == 2 and "packet loss" in found[0] and "round trip" in found[1]
