"""The parity harness (the relay's analyzer in headless Chromium), as the browser tests open it."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager

from playwright.sync_api import Page

from app.protocol.opencv import OpenCvBuild
from app.server.config import Settings
from app.tools import parity


def open_harness(
    build: OpenCvBuild | None = None,
) -> AbstractContextManager[parity.Harness]:
    """The harness on a development server that asks for no token, with OpenCV.js ``build``
    (None: the relay's, as ``autopilot parity`` loads by default)."""
    return parity.open_harness(Settings(environment="development", token=None), build)


@contextmanager
def analyzer_page(helpers_js: str | None = None) -> Iterator[Page]:
    """The harness page, with ``helpers_js`` (the source of a JS function) evaluated in it first."""
    with open_harness() as harness:
        if helpers_js is not None:
            harness.page.evaluate(helpers_js)
        yield harness.page
