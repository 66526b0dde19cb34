"""A burst of lock and unlock clicks never stalls the goals: the relay runs them through
core/one-at-a-time.js, so the analyzer's snapshots never queue behind more than two of them.

Headless Chromium on the parity page, with the relay's analyzer: the snapshot loop analyses
frames back to back while goals are counted over a window, first with no clicks (the baseline),
then right after 300 lock/unlock clicks, in the same run.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from playwright.sync_api import Page

from app.protocol.relay_profiles import DEFAULT_PROFILE
from tests.helpers.harness import analyzer_page
from tests.vision.test_snapshot_loop import FACE_SIZE, HEIGHT, WIDTH, faces

pytestmark = [pytest.mark.browser, pytest.mark.slow]

WINDOW_MS = 1000
CLICKS = 300

# Goals counted over WINDOW_MS of back-to-back frames: with no clicks, then after CLICKS clicks
# sent as the relay page sends them (through one OneAtATime, not waited for).
BURST = """async ({ frame, profile, windowMs, clicks, centre }) => {
  const { SnapshotLoop } = await import('/static/js/core/snapshot-loop.js');
  const { OneAtATime } = await import('/static/js/core/one-at-a-time.js');
  await window.analyzer.unlock(); // another test's lock
  const rgba = { width: %d, height: %d,
    data: Uint8ClampedArray.from(atob(frame), (c) => c.charCodeAt(0)) };
  let goals = 0;
  const loop = new SnapshotLoop({ analyzer: window.analyzer, profile,
    op: window.analyzer.defaultOp, sendGoal: () => { goals += 1; return true; } });
  loop.start();
  const counted = async () => {
    const before = goals;
    const end = performance.now() + windowMs;
    while (performance.now() < end) await loop.frame({ ...rgba, data: rgba.data.slice() });
    return goals - before;
  };
  await counted(); // warm up
  const baseline = await counted();
  const requests = new OneAtATime();
  const answered = [];
  for (let n = 0; n < clicks; n += 1) {
    const click = n %% 2 === 0
      ? () => loop.lockAt(centre[0], centre[1]) : () => loop.unlock('released');
    answered.push(requests.run(click));
  }
  const burst = await counted();
  await Promise.all(answered);
  return { baseline, burst, dropped: requests.dropped };
}""" % (WIDTH, HEIGHT)  # noqa: UP031 -- the JS template has braces of its own


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with analyzer_page() as opened:
        yield opened


def test_goals_flow_on_after_a_burst_of_300_lock_and_unlock_clicks(page: Page) -> None:
    at = (40, 40)
    # Clicks beside the face: each lock request searches around the click at full resolution,
    # the costliest a click can ask of the analyzer.
    beside = [WIDTH - 60, HEIGHT - 60]
    got = page.evaluate(
        BURST,
        {
            "frame": faces([(*at, FACE_SIZE)], 1),
            "profile": DEFAULT_PROFILE,
            "windowMs": WINDOW_MS,
            "clicks": CLICKS,
            "centre": beside,
        },
    )
    assert got["baseline"] >= 5, got  # the window means something
    # The window right after the burst keeps at least half the baseline's goals.
    assert got["burst"] * 2 >= got["baseline"], got
    assert got["dropped"] == CLICKS - 2, got
