"""core/glass-to-glass.js, in a real page: a frame's capture time and its presentation at the
client make one sample whichever arrives first; frames never shown or never timed make none; a
capture and a presentation 10 s apart are different frames of the same number (a vehicle that
restarted); the live figure is the median and 95th percentile of the latest samples."""

from __future__ import annotations

from typing import Any

import pytest
from playwright.sync_api import Browser

from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

# Unix ms; the vehicle's and the client's clocks agree here.
T0 = 1_700_000_000_000

SEQUENCES = """(t0) => {
  const { GlassToGlass } = window['glass-to-glass'];
  const out = {};

  // Frame 1: timed, then shown 40 ms later. Frame 2: shown first, timed after (the batch of
  // capture times comes every 0.1 s). Frame 3: timed, never shown. Frame 4: shown, never timed.
  let g = new GlassToGlass();
  g.captured(1, t0);
  g.presented(1, t0 + 40);
  g.presented(2, t0 + 33 + 55);
  g.captured(2, t0 + 33);
  g.captured(3, t0 + 66);
  g.presented(4, t0 + 99 + 10);
  out.samples = g.samples.toArray();
  out.count = g.count;
  // Shown twice (a repeated callback): counted once.
  g.presented(1, t0 + 80);
  out.countAfterRepeat = g.count;

  // A restarted vehicle numbers from 0 again: an old capture of frame 7, a presentation of the
  // new frame 7 a minute later, is no sample; after reset() nothing old is matched.
  g = new GlassToGlass();
  g.captured(7, t0);
  g.presented(7, t0 + 60_000);
  out.minuteApart = g.count;
  g.captured(8, t0);
  g.reset();
  g.presented(8, t0 + 30);
  out.afterReset = g.count;

  // The figure over the latest `recent` samples: the older ones have left it.
  g = new GlassToGlass({ recent: 4 });
  [500, 500, 10, 20, 30, 40].forEach((ms, frame) => {
    g.captured(frame, t0 + frame * 33);
    g.presented(frame, t0 + frame * 33 + ms);
  });
  out.summary = g.summary();
  out.emptySummary = new GlassToGlass().summary();
  // Waiting frames are bounded: the oldest of more than `waiting` is forgotten.
  g = new GlassToGlass({ waiting: 2 });
  g.captured(1, t0);
  g.captured(2, t0);
  g.captured(3, t0);
  g.presented(1, t0 + 50);
  g.presented(3, t0 + 50);
  out.bounded = g.samples.toArray();
  // The quantiles interpolate between the nearest ranks, whatever order the samples came in.
  const measured = (samples) => {
    const m = new GlassToGlass();
    samples.forEach((ms, frame) => {
      m.captured(frame, t0);
      m.presented(frame, t0 + ms);
    });
    return m.summary();
  };
  out.quantiles = [measured([4, 1, 3, 2]).p50Ms, measured([1, 2, 3, 4, 5]).p95Ms];
  return out;
}"""


def test_glass_to_glass_pairs_frames_either_way(server: RunningServer, browser: Browser) -> None:
    with module_page(server, browser, "core/glass-to-glass") as page:
        found: dict[str, Any] = page.evaluate(SEQUENCES, T0)
    assert found["samples"] == [40, 55] and found["count"] == 2
    assert found["countAfterRepeat"] == 2
    assert found["minuteApart"] == 0
    assert found["afterReset"] == 0
    assert found["summary"] == {
        "p50Ms": 25,
        "p95Ms": pytest.approx(38.5),
        "lastMs": 40,
        "frames": 6,
    }
    assert found["emptySummary"] is None
    assert found["bounded"] == [50]
    assert found["quantiles"] == [2.5, pytest.approx(4.8)]


STALE = """(t0) => {
  const { GlassToGlass } = window['glass-to-glass'];
  const g = new GlassToGlass();
  const out = { before: g.stale(t0) };
  g.captured(1, t0);
  g.presented(1, t0 + 40);
  // Shown at t0 + 40: live for 2 s after, stale once no frame has been measured for longer.
  out.live = [g.stale(t0 + 40), g.stale(t0 + 2040)];
  out.stale = g.stale(t0 + 2041);
  // A frame timed but never shown measures nothing: the figure stays stale.
  g.captured(2, t0 + 2100);
  out.timedOnly = g.stale(t0 + 2200);
  g.presented(2, t0 + 2150);
  out.again = g.stale(t0 + 2200);
  return out;
}"""


def test_the_figure_is_stale_two_seconds_after_the_last_frame_measured(
    server: RunningServer, browser: Browser
) -> None:
    with module_page(server, browser, "core/glass-to-glass") as page:
        found: dict[str, Any] = page.evaluate(STALE, T0)
    assert found == {
        "before": True,
        "live": [False, False],
        "stale": True,
        "timedOnly": True,
        "again": False,
    }
