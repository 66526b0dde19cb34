"""The relay's Prometheus metrics (``autopilot relay --metrics-port``, with or without ``--pool``).

What the relay measures lives in its page (``relay-stats.js``, exposed as
``window.autopilotStatus``); once a second the service asks each page it runs for what changed
since the last poll (``page.evaluate``) and exports it. One relay process serves one room, so
no series carries a room; a pool's pages are added together (its rooms are in Redis and on the
``/fleet`` page, not in label values that would grow with the fleet).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Final

from playwright.async_api import Error as PlaywrightError
from playwright.async_api import Page
from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram

from app.metrics import serve_metrics
from app.relay.page import RATE_WINDOW_S
from app.supervise import run_until_stopped

log = logging.getLogger(__name__)

POLL_PERIOD_S: Final = 1.0
# Seconds from snapshot to goal: the relay profiles aim at 30 to 300 ms per snapshot.
PROCESSING_BUCKETS: Final = (0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0)

# ``since``: the page's snapshot count at the previous poll. Only the delays of the snapshots
# after it are returned (at most the page's ring of recent ones).
POLL_JS = """([since, windowMs]) => {
  const s = window.autopilotStatus;
  if (!s) return null;
  const fresh = s.snapshots - since;
  const ms = fresh > 0 ? s.processingMs : [];
  const now = performance.now();
  return {
    snapshots: s.snapshots,
    goalsSent: s.goalsSent,
    piloting: s.piloting,
    processingMs: ms.slice(Math.max(ms.length - fresh, 0)),
    goalsPerS: s.goalTimes.filter((t) => now - t <= windowMs).length / (windowMs / 1000),
  };
}"""

Pages = Callable[[], dict[str, Page]]


@dataclass
class _Seen:
    """A page's counts at the previous poll (a page started again counts from 0)."""

    snapshots: int = 0
    goals_sent: int = 0


class RelayMetrics:
    """The relay's series, in a registry of their own, fed by :meth:`poll`."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.processing = Histogram(
            "autopilot_relay_processing_seconds",
            "Snapshot taken to goal sent (or analysis done when nothing was found)",
            buckets=PROCESSING_BUCKETS,
            registry=self.registry,
        )
        self.snapshots = Counter(
            "autopilot_relay_snapshots_total", "Snapshots analysed", registry=self.registry
        )
        self.goals_sent = Counter(
            "autopilot_relay_goals_sent_total", "Goals sent to the vehicle", registry=self.registry
        )
        self.goals_per_s = Gauge(
            "autopilot_relay_goals_per_second",
            f"Goals sent per second over the last {RATE_WINDOW_S:g} s (a pool: all its rooms)",
            registry=self.registry,
        )
        self.piloting = Gauge(
            "autopilot_relay_piloting",
            "Relay pages piloting (a client pressed Start Piloting): 0 or 1, a pool: its rooms",
            registry=self.registry,
        )
        self.pages = Gauge(
            "autopilot_relay_pages",
            "Relay pages that answered the last poll",
            registry=self.registry,
        )
        self._seen: dict[str, _Seen] = {}

    async def poll(self, pages: Pages, period_s: float = POLL_PERIOD_S) -> None:
        """Poll ``pages()`` (key -> page) every ``period_s`` until cancelled."""
        while True:
            await self.poll_once(pages())
            await asyncio.sleep(period_s)

    async def poll_once(self, pages: dict[str, Page]) -> None:
        """Ask each page what changed since the last poll and export it."""
        self._seen = {key: self._seen.get(key, _Seen()) for key in pages}
        answered, piloting, goals_per_s = 0, 0, 0.0
        for key, page in pages.items():
            seen = self._seen[key]
            try:
                status: dict[str, Any] | None = await page.evaluate(
                    POLL_JS, [seen.snapshots, RATE_WINDOW_S * 1000]
                )
            except PlaywrightError as exc:
                log.debug("no metrics from relay page %r: %s", key, exc.message.splitlines()[0])
                continue
            if status is None:
                continue  # still loading
            if status["snapshots"] < seen.snapshots:
                # A new page (the old one died): its counts start from 0, and this poll's
                # samples were taken from the new page's start.
                self._seen[key] = seen = _Seen()
                status = await page.evaluate(POLL_JS, [0, RATE_WINDOW_S * 1000])
                if status is None:
                    continue
            answered += 1
            piloting += bool(status["piloting"])
            goals_per_s += status["goalsPerS"]
            for ms in status["processingMs"]:
                self.processing.observe(ms / 1000)
            self.snapshots.inc(status["snapshots"] - seen.snapshots)
            self.goals_sent.inc(max(status["goalsSent"] - seen.goals_sent, 0))
            seen.snapshots, seen.goals_sent = status["snapshots"], status["goalsSent"]
        self.pages.set(answered)
        self.piloting.set(piloting)
        self.goals_per_s.set(goals_per_s)


def run_with_metrics(
    args: argparse.Namespace, run: Callable[[asyncio.Event], Awaitable[None]], pages: Pages
) -> int:
    """``run`` until SIGINT/SIGTERM (:func:`~app.supervise.run_until_stopped`); with
    ``--metrics-port``, with the listener open and ``pages()`` polled meanwhile.

    Returns the exit status: 1 when the metrics listener cannot be opened.
    """
    metrics = RelayMetrics()
    try:
        server = serve_metrics(args, metrics.registry)
    except OSError as exc:
        log.error("%s", exc)
        return 1
    if server is None:
        asyncio.run(run_until_stopped(run))
        return 0

    async def run_polled(stop: asyncio.Event) -> None:
        poller = asyncio.create_task(metrics.poll(pages), name="relay-metrics")
        try:
            await run(stop)
        finally:
            poller.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await poller

    try:
        asyncio.run(run_until_stopped(run_polled))
    finally:
        server.close()
    return 0
