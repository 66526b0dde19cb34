"""core/one-at-a-time.js: at most one request runs, only the newest waits, the rest are dropped."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.browser]


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/one-at-a-time", "oneAtATime") as opened:
        yield opened


def test_a_burst_of_300_runs_the_first_and_the_newest_only(page: Page) -> None:
    got = page.evaluate(
        """async () => {
             const requests = new oneAtATime.OneAtATime();
             const ran = [];
             let running = 0, most = 0;
             const job = (n) => async () => {
               running += 1; most = Math.max(most, running);
               await new Promise((resolve) => setTimeout(resolve, 5));
               ran.push(n); running -= 1;
               return n;
             };
             const answers = await Promise.all(
               Array.from({ length: 300 }, (_, n) => requests.run(job(n))));
             const after = await requests.run(job(300));  // idle again: runs at once
             return { ran, most, answers, after, dropped: requests.dropped };
           }"""
    )
    assert got["ran"] == [0, 299, 300]
    assert got["most"] == 1
    assert got["answers"][0] == 0 and got["answers"][299] == 299
    assert set(got["answers"][1:299]) == {None}
    assert (got["after"], got["dropped"]) == (300, 298)


def test_a_failed_request_is_reported_and_the_next_still_runs(page: Page) -> None:
    got = page.evaluate(
        """async () => {
             const requests = new oneAtATime.OneAtATime();
             const failing = requests.run(async () => { throw new Error('no frame yet'); });
             const next = requests.run(async () => 'locked');
             const error = await failing.catch((err) => err.message);
             return [error, await next];
           }"""
    )
    assert got == ["no frame yet", "locked"]
