"""core/rtp-timestamps.js: the clients' RTP timestamps go on from one vehicle's stream to the
next."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.browser]

# A frame at 30/s on the 90 kHz video clock: from one stream's last frame to the next's first.
STEP = 90_000 // 30


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/rtp-timestamps", "rtpTimestamps") as opened:
        yield opened


def timeline(page: Page, frames: list[tuple[str, int]]) -> list[int]:
    """The timestamps handed out for ``frames``, (stream, own timestamp) pairs, in order."""
    result: list[int] = page.evaluate(
        """(frames) => {
             const timestamps = new rtpTimestamps.ContinuousTimestamps();
             return frames.map(([stream, ts]) => timestamps.next(stream, ts));
           }""",
        frames,
    )
    return result


def test_the_first_stream_keeps_its_own_timestamps(page: Page) -> None:
    own = [4_000_000_000, 4_000_003_000, 4_000_006_000]
    assert timeline(page, [("a", ts) for ts in own]) == own


@pytest.mark.parametrize("start", [1_000, 3_999_000_000, 2**31])
def test_a_later_stream_follows_the_last_frame_wherever_it_starts(page: Page, start: int) -> None:
    got = timeline(
        page,
        [("a", 2_000_000_000), ("a", 2_000_003_000)]
        + [("b", start), ("b", start + 3_000), ("b", start + 9_000)],
    )
    assert got[2:] == [2_000_003_000 + STEP, 2_000_006_000 + STEP, 2_000_012_000 + STEP]


def test_timestamps_wrap_at_2_to_the_32(page: Page) -> None:
    got = timeline(page, [("a", 2**32 - 2_000), ("b", 5), ("b", 3_005)])
    assert got == [2**32 - 2_000, 1_000, 4_000]


def test_a_stream_that_comes_back_after_another_is_shifted_again(page: Page) -> None:
    got = timeline(page, [("a", 100), ("b", 9_000_000), ("a", 200)])
    assert got == [100, 100 + STEP, 100 + 2 * STEP]
