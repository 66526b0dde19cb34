"""Fixtures for the end-to-end tests: the server, headless Chromium, a fake camera video.

Pages run in Debian's Chromium through Playwright (``app.chromium``), one browser per module
whose fake camera (a per-browser flag) shows the face on the left; a scene with another camera
launches its own browser for the vehicle. Every page's screenshot and console are kept under
``artifacts/<test>/`` whether the test passes or fails.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlencode

import pytest
from playwright.sync_api import Browser, ConsoleMessage, Page, Playwright, expect, sync_playwright

from app.chromium import launch_options
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from e2e.helpers import FPS, face_frame, write_y4m

REPO = Path(__file__).resolve().parents[1]
ARTIFACTS = REPO / "artifacts"

# Generous waits: three Chromium pages and OpenCV.js share two loaded cores. Waits end as soon
# as their condition holds, so this only costs time when something is really wrong.
expect.set_options(timeout=60_000)


@pytest.fixture(scope="session")
def face_left_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The fake camera: obama.jpg's face on the LEFT third of the frame, two seconds looped."""
    path = tmp_path_factory.getbasetemp() / "face-left.y4m"
    if not path.exists():
        write_y4m(path, face_frame("obama.jpg", "left"), frames=2 * FPS)
    return path


@pytest.fixture
def server() -> Iterator[RunningServer]:
    """A fresh server (and simulated turtle) per test, on a free port."""
    # Independent of the environment the tests run in (no token, no ICE servers).
    running = start_in_thread(Settings(environment="development", token=None, ice_servers=[]))
    yield running
    running.stop()


# Playwright's sync API marks the thread's event loop as running for as long as it is open, and
# the asyncio tests cannot run beside it: module scope closes it before any other module's tests,
# so the suite passes in any order and under any split between xdist workers.
@pytest.fixture(scope="module")
def playwright() -> Iterator[Playwright]:
    with sync_playwright() as pw:
        yield pw


@pytest.fixture(scope="module")
def browser(playwright: Playwright, face_left_video: Path) -> Iterator[Browser]:
    """Chromium for the role pages, each in a context of its own; its camera (a per-browser
    flag) shows the face on the left, and only vehicle pages ask for it."""
    launched = playwright.chromium.launch(**launch_options(face_left_video))
    yield launched
    launched.close()


@pytest.fixture(scope="module")
def vehicle_browser(browser: Browser) -> Browser:
    """The vehicle pages' Chromium: the same as the others' (a launch costs more than most
    tests); a scene with another camera launches its own."""
    return browser


@dataclass
class OpenedPage:
    role: str
    page: Page
    console: list[str] = field(default_factory=list)


OpenRole = Callable[..., Page]


@pytest.fixture
def open_role(request: pytest.FixtureRequest, server: RunningServer) -> Iterator[OpenRole]:
    """``open_role(role, browser, **query)`` opens a role page in its own browser context;
    ``init_script`` runs in it before the page's own scripts (a stubbed browser API, say),
    ``device`` sets the context's options (a phone's viewport and touch screen, say), and
    ``token`` goes in the URL's fragment (``#token=...``), as ``autopilot token`` prints it.

    At teardown each page's screenshot and console log go to ``artifacts/<test>/``.
    """
    opened: list[OpenedPage] = []

    def open_page(
        role: str,
        browser: Browser,
        init_script: str | None = None,
        device: Mapping[str, Any] | None = None,
        token: str | None = None,
        **query: str,
    ) -> Page:
        context = browser.new_context(
            **{"viewport": {"width": 1280, "height": 960}, **(device or {})}
        )
        context.set_default_timeout(60_000)
        if init_script is not None:
            context.add_init_script(init_script)
        page = context.new_page()
        # Two pages of one role keep their own artifacts: name them by their peer name.
        entry = OpenedPage(f"{role}-{query['name']}" if "name" in query else role, page)

        def keep(message: ConsoleMessage) -> None:
            entry.console.append(f"{message.type}: {message.text}")

        page.on("console", keep)
        # The relay's OpenCV.js runs in a Web Worker, whose console is separate.
        page.on("worker", lambda worker: worker.on("console", keep))
        page.on("pageerror", lambda error: entry.console.append(f"pageerror: {error}"))
        opened.append(entry)
        fragment = "" if token is None else f"#token={token}"
        page.goto(f"{server.url}/{role}?{urlencode(query)}{fragment}")
        return page

    yield open_page

    folder = artifacts_dir(request)
    # Every screenshot before any page closes, so each shows the session as it ended.
    for entry in opened:
        if not entry.page.is_closed():
            entry.page.screenshot(path=str(folder / f"{entry.role}.png"), full_page=True)
    for entry in opened:
        (folder / f"{entry.role}.console.log").write_text("\n".join(entry.console) + "\n")
        entry.page.context.close()


def open_room(
    open_role: OpenRole, room: str, vehicle_browser: Browser, browser: Browser, client: str
) -> tuple[Page, Page, Page]:
    """The vehicle, relay and client (named ``client``) pages of ``room``, each joining it by
    itself (``auto=1``); the vehicle's camera is ``vehicle_browser``'s."""
    query = {"room": room, "auto": "1"}
    vehicle = open_role("vehicle", vehicle_browser, name="vehicle", **query)
    relay = open_role("relay", browser, name="relay", **query)
    return vehicle, relay, open_role("client", browser, name=client, **query)


def artifacts_dir(request: pytest.FixtureRequest) -> Path:
    """``artifacts/<test name>/``, created on demand."""
    folder = ARTIFACTS / re.sub(r"[^\w.-]+", "_", request.node.name)
    folder.mkdir(parents=True, exist_ok=True)
    return folder
