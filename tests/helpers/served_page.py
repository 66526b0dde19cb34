"""A page of a development server in headless Chromium, to import the pages' JS modules in."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from playwright.sync_api import Page, sync_playwright

from app.chromium import launch_options
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread


@contextmanager
def served_page() -> Iterator[Page]:
    """The index page (its config holds the protocol) of a server that asks for no token, in a
    browser of its own: one per test module, opened by a module-scoped fixture."""
    server: RunningServer = start_in_thread(Settings(environment="development", token=None))
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(**launch_options())
            opened = browser.new_page()
            opened.goto(server.url + "/")
            yield opened
            browser.close()
    finally:
        server.stop()
