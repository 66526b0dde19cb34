"""Fixtures shared by the whole test suite."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path

import pytest
import pytest_asyncio
from playwright.async_api import Browser, Page, async_playwright

from app.chromium import launch_options
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from app.tools.redis_server import redis_server
from tests.helpers.sockets import Records


@pytest.fixture
def settings() -> Settings:
    """Settings independent of the environment the tests run in."""
    return Settings(environment="development", token=None)


@pytest.fixture
def start_server() -> Iterator[Callable[[Settings], RunningServer]]:
    """Start the real app under uvicorn on a free port; every server started is stopped after."""
    servers: list[RunningServer] = []

    def start(settings: Settings) -> RunningServer:
        server = start_in_thread(settings)
        servers.append(server)
        return server

    yield start
    for server in servers:
        server.stop()


@pytest.fixture
def server(start_server: Callable[[Settings], RunningServer], settings: Settings) -> RunningServer:
    """The app with default settings, running on a free port."""
    return start_server(settings)


@pytest.fixture
def redis_url(tmp_path: Path) -> Iterator[str]:
    """A fresh Debian ``redis-server`` on a free port, stopped after the test (the fleet's and
    the relay pool's tests)."""
    with redis_server(tmp_path) as url:
        yield url


@pytest.fixture
def start_instance(
    redis_url: str, start_server: Callable[[Settings], RunningServer]
) -> Callable[[], RunningServer]:
    """Start one more instance of the service on the test's Redis (in this process)."""

    def start() -> RunningServer:
        return start_server(Settings(environment="development", token=None, redis_url=redis_url))

    return start


@pytest.fixture
def server_log() -> Iterator[Records]:
    """Every record the server logs during the test, uvicorn's included."""
    records = Records()
    loggers = [
        logging.getLogger(),
        logging.getLogger("uvicorn"),
        logging.getLogger("uvicorn.error"),
    ]
    for logger in loggers:
        logger.addHandler(records)
    yield records
    for logger in loggers:
        logger.removeHandler(records)


@pytest_asyncio.fixture(scope="module", loop_scope="module")
async def module_browser() -> AsyncIterator[Browser]:
    """One headless Chromium for a module of async browser tests (its launch costs more than
    most of them), on the module's event loop: the module marks its tests
    ``pytest.mark.asyncio(loop_scope="module")``."""
    async with async_playwright() as playwright:
        launched = await playwright.chromium.launch(**launch_options())
        try:
            yield launched
        finally:
            await launched.close()


@pytest_asyncio.fixture(loop_scope="module")
async def context_page(module_browser: Browser) -> AsyncIterator[Page]:
    """A page of ``module_browser`` in a browser context of its own, closed after the test."""
    context = await module_browser.new_context()
    try:
        yield await context.new_page()
    finally:
        await context.close()
