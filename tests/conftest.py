"""Fixtures shared by the whole test suite."""

from __future__ import annotations

from collections.abc import Callable, Iterator

import pytest

from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread


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
