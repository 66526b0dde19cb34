"""The relay's search window (window.js) agrees with the Python rule (app/vision/window.py).

``autopilot parity`` compares the windowed path box for box on photos; this checks the two
functions that shape the window, on a grid of boxes, factors and limits that reaches every
branch (clipping at each edge, empty windows, limits on either side of the target's sizes).
"""

from __future__ import annotations

import random
from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from app.vision import window
from e2e.helpers import module_page

pytestmark = [pytest.mark.browser]

SAMPLES = 400
WIDTH, HEIGHT = 256, 192


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/tracking-window", name="searchWindow") as opened:
        yield opened


def samples() -> list[tuple[window.Box, float, float, float, window.Size, window.Size]]:
    rng = random.Random(11)
    cases = []
    for _ in range(SAMPLES):
        w, h = rng.randint(1, 400), rng.randint(1, 400)
        box = (rng.randint(-200, 700), rng.randint(-200, 500), w, h)
        factor = rng.choice([1.0, 2.5, 640 / 256, 640 / 480, 3.0])
        limit = rng.randint(0, 120)
        min_size = rng.choice([(0, 0), (24, 24), (limit, limit // 2)])
        max_size = rng.choice([(0, 0), (limit, limit), (limit, 0)])
        margin, ratio = rng.uniform(0.1, 1.0), rng.uniform(1.01, 3.0)
        cases.append((box, factor, margin, ratio, min_size, max_size))
    return cases


def test_search_region_and_sizes_match_python(page: Page) -> None:
    cases = samples()
    got = page.evaluate(
        """([cases, width, height]) => cases.map(([box, factor, margin, ratio, lo, hi]) => {
          const region = searchWindow.searchRegion(box, factor, width, height, margin);
          const sizes = searchWindow.searchSizes(box, factor, ratio, lo, hi);
          const found = region && [region.x, region.y, region.width, region.height];
          return [found, sizes.min, sizes.max];
        })""",
        [cases, WIDTH, HEIGHT],
    )
    empty = limited = 0
    for case, have in zip(cases, got, strict=True):
        box, factor, margin, ratio, min_size, max_size = case
        region = window.search_region(box, factor, WIDTH, HEIGHT, margin)
        smallest, largest = window.search_sizes(box, factor, ratio, min_size, max_size)
        assert have == [region and list(region), list(smallest), list(largest)], case
        empty += region is None
        limited += max_size[0] > 0 and max_size[1] > 0 and largest[0] == max_size[0]
    # Both kinds of branch occurred, so agreeing means something.
    assert 0 < empty < SAMPLES and 0 < limited < SAMPLES


def test_source_rect_matches_python(page: Page) -> None:
    rng = random.Random(12)
    cases = []
    for _ in range(SAMPLES):
        width, height = rng.choice([(640, 480), (1280, 720), (800, 600), (1366, 768), (320, 240)])
        detect_width = rng.choice([256, 320, 480])
        size = (detect_width, int(height * detect_width / width + 0.5))
        x0, y0 = rng.randrange(size[0]), rng.randrange(size[1])
        region = (x0, y0, rng.randint(1, size[0] - x0), rng.randint(1, size[1] - y0))
        cases.append((region, width, height, size))
    got = page.evaluate(
        """(cases) => cases.map(([[x, y, width, height], w, h, [sw, sh]]) => {
          const size = { width: sw, height: sh };
          const rects = searchWindow.sourceRect({ x, y, width, height }, w, h, size);
          const box = (r) => [r.x, r.y, r.width, r.height];
          return rects && [box(rects.reduced), box(rects.source)];
        })""",
        cases,
    )
    exact = 0
    for case, have in zip(cases, got, strict=True):
        rects = window.source_rect(*case)
        assert have == (rects and [list(rects[0]), list(rects[1])]), case
        exact += rects is not None
    # Both grids occurred: exact ones (640 → 256) and inexact ones (640 → 480).
    assert 0 < exact < SAMPLES
