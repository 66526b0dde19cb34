"""``autopilot relay``: the relay page in headless Chromium, kept alive until told to stop.

The page joins its room by itself (``?auto=1``). If the page crashes, is closed or the browser
dies, it is started again after a short backoff; when told to stop it closes the browser.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from pathlib import Path

from playwright.async_api import Browser, ConsoleMessage, Page, Playwright, async_playwright
from playwright.async_api import Error as PlaywrightError

from app.chromium import launch_options
from app.relay.page import PAGE_LOAD_TIMEOUT_MS, loggable, relay_url
from app.supervise import Backoff, sleep_unless

log = logging.getLogger(__name__)

RESTART_FIRST_S = 1.0
RESTART_CAP_S = 15.0


class RelayService:
    """Keeps one headless relay page running in ``room``."""

    def __init__(
        self,
        server: str,
        room: str = "default",
        name: str = "relay",
        profile: str = "default",
        token: str | None = None,
        ca_file: Path | None = None,
    ) -> None:
        self.url = relay_url(server, room, name, profile, token)
        self.launch_options = launch_options(trust_ca=ca_file)
        self.page: Page | None = None
        self.starts = 0  # pages started, the first included
        self.started = asyncio.Event()  # set each time a page has loaded

    def pages(self) -> dict[str, Page]:
        """The running page, for the metrics' poll (none while it loads or restarts)."""
        return {} if self.page is None else {"relay": self.page}

    async def run(self, stop: asyncio.Event) -> None:
        """Run until ``stop`` is set."""
        backoff = Backoff(RESTART_FIRST_S, RESTART_CAP_S, jitter=0)
        async with async_playwright() as playwright:
            while not stop.is_set():
                try:
                    reason = await self._run_browser(playwright, stop)
                except PlaywrightError as exc:
                    # Chromium failed to start or vanished mid-call: try again, like a crash.
                    reason = exc.message.splitlines()[0]
                if stop.is_set():
                    break
                delay = backoff.next()
                log.warning("relay page died (%s); restarting in %.0f s", reason, delay)
                await sleep_unless(stop, delay)

    async def _run_browser(self, playwright: Playwright, stop: asyncio.Event) -> str:
        browser = await playwright.chromium.launch(**self.launch_options)
        try:
            return await self._run_page(browser, stop)
        finally:
            self.page = None
            self.started.clear()
            if browser.is_connected():
                with contextlib.suppress(PlaywrightError):
                    # The page's socket and peer connections close with it: the room sees the
                    # relay leave.
                    await browser.close()

    async def _run_page(self, browser: Browser, stop: asyncio.Event) -> str:
        ended: asyncio.Queue[str] = asyncio.Queue()
        browser.on("disconnected", lambda _: ended.put_nowait("browser disconnected"))
        page = await browser.new_page()
        page.on("crash", lambda _: ended.put_nowait("page crashed"))
        page.on("close", lambda _: ended.put_nowait("page closed"))
        page.on("console", _log_console)
        page.on("pageerror", lambda error: log.warning("relay page error: %s", error))
        try:
            await page.goto(self.url, timeout=PAGE_LOAD_TIMEOUT_MS)
        except PlaywrightError as exc:
            return f"could not load {loggable(self.url)}: {exc.message.splitlines()[0]}"
        self.page = page
        self.starts += 1
        self.started.set()
        log.info("relay page running: %s", loggable(self.url))
        stopping = asyncio.create_task(stop.wait())
        dying = asyncio.create_task(ended.get())
        try:
            await asyncio.wait({stopping, dying}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            stopping.cancel()
            dying.cancel()
        return "stopped" if stop.is_set() else dying.result()


def _log_console(message: ConsoleMessage) -> None:
    level = logging.WARNING if message.type == "error" else logging.DEBUG
    log.log(level, "relay page console: %s", message.text)
