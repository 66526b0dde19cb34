"""``autopilot relay``: the relay page in headless Chromium, kept alive until told to stop.

The page joins its room by itself (``?auto=1``). If the page crashes, is closed or the browser
dies, it is started again after a short backoff; SIGINT or SIGTERM closes the browser and exits
with status 0.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import ssl
import urllib.error
import urllib.request
from pathlib import Path

from playwright.async_api import Browser, ConsoleMessage, Page, Playwright, async_playwright
from playwright.async_api import Error as PlaywrightError

from app.arguments import add_relay_profile, positive_integer
from app.metrics import add_metrics_arguments
from app.protocol.urls import ServerUrlError, page_url, server_base, untrusted_hint
from app.supervise import Backoff, sleep_unless
from app.tools.browser import BrowserNotFound, chromium_path, launch_options
from app.tools.relay_metrics import run_with_metrics

log = logging.getLogger(__name__)

RESTART_FIRST_S = 1.0
RESTART_CAP_S = 15.0
PAGE_LOAD_TIMEOUT_MS = 30_000
# Read when --token is not given, so the token stays out of the process list.
TOKEN_ENV = "AUTOPILOT_ACCESS_TOKEN"


class RelayServiceError(RuntimeError):
    """The relay cannot start at all (no browser, server unreachable)."""


def relay_url(server: str, room: str, name: str, profile: str, token: str | None = None) -> str:
    """The relay page URL that joins ``room`` unattended, without a video preview nobody
    watches; the token rides in the fragment, which never reaches the server's access log."""
    url = page_url(server, "relay", room, name=name, auto=1, profile=profile, preview=0)
    return url + (f"#token={token}" if token else "")


def check_server(server: str, ca_file: Path | None = None) -> None:
    """Fail fast, with the reason, when ``server`` does not answer ``/healthz`` (over HTTPS:
    with a certificate the system or ``ca_file`` trusts)."""
    try:
        base = server_base(server)
    except ServerUrlError as exc:
        raise RelayServiceError(str(exc)) from None
    try:
        context = ssl.create_default_context(cafile=None if ca_file is None else str(ca_file))
        with urllib.request.urlopen(f"{base}/healthz", timeout=10, context=context) as response:
            response.read()
    except (urllib.error.URLError, OSError) as exc:
        raise RelayServiceError(
            f"cannot reach the server at {server}: {exc}{untrusted_hint(exc)}"
        ) from exc


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
                    await self._leave_and_close(browser)

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
            address = self.url.split("#", 1)[0]
            return f"could not load {address}: {exc.message.splitlines()[0]}"
        self.page = page
        self.starts += 1
        self.started.set()
        log.info("relay page running: %s", self.url.split("#", 1)[0])
        stopping = asyncio.create_task(stop.wait())
        dying = asyncio.create_task(ended.get())
        try:
            await asyncio.wait({stopping, dying}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            stopping.cancel()
            dying.cancel()
        return "stopped" if stop.is_set() else dying.result()

    async def _leave_and_close(self, browser: Browser) -> None:
        page = self.page
        if page is not None and not page.is_closed():
            # Closing the page runs its unload handlers: the relay stops the vehicle first.
            await page.close(run_before_unload=True)
        await browser.close()


def _log_console(message: ConsoleMessage) -> None:
    level = logging.WARNING if message.type == "error" else logging.DEBUG
    log.log(level, "relay page console: %s", message.text)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot relay``."""
    parser.add_argument("--server", required=True, help="server base URL, e.g. http://host:8000")
    parser.add_argument("--room", default="default", help="room to join (default: default)")
    parser.add_argument("--name", default="relay", help="peer name (default: relay)")
    add_relay_profile(parser, "relay profile")
    parser.add_argument(
        "--token",
        default=os.environ.get(TOKEN_ENV),
        help=f"relay token for the room, from `autopilot token` (default: ${TOKEN_ENV})",
    )
    parser.add_argument(
        "--ca-file", type=Path, metavar="PEM", help="trust this CA for an https:// server"
    )
    parser.add_argument(
        "--pool",
        action="store_true",
        help="serve every room with a vehicle and no relay (needs Redis; --room is ignored)",
    )
    parser.add_argument(
        "--max-rooms", type=positive_integer, help="with --pool: serve at most N rooms"
    )
    parser.add_argument("--redis-url", help="with --pool: Redis URL (default: AUTOPILOT_REDIS_URL)")
    add_metrics_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the headless relay (or, with ``--pool``, a relay pool) until SIGINT/SIGTERM."""
    if args.pool:
        from app.tools import relay_pool  # only a pool needs Redis

        return relay_pool.run(args)
    try:
        check_server(args.server, args.ca_file)
        chromium_path()
        service = RelayService(
            args.server, args.room, args.name, args.profile, args.token, args.ca_file
        )
    except (RelayServiceError, BrowserNotFound) as exc:
        log.error("%s", exc)
        return 1
    except (OSError, ValueError) as exc:
        log.error("cannot use --ca-file %s: %s", args.ca_file, exc)
        return 1
    status = run_with_metrics(args, service.run, service.pages)
    log.info("relay stopped")
    return status
