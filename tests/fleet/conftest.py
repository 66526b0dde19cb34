"""Fixtures of the fleet tests: a real Redis per test and app instances sharing it."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from app.config import Settings
from app.serve import RunningServer
from tests.helpers.redis_server import redis_server


@pytest.fixture
def redis_url(tmp_path: Path) -> Iterator[str]:
    """A fresh Debian ``redis-server`` on a free port, stopped after the test."""
    with redis_server(tmp_path) as url:
        yield url


@pytest.fixture
def start_instance(
    start_server: Callable[[Settings], RunningServer], redis_url: str
) -> Callable[[], RunningServer]:
    """Start one more instance of the service on the test's Redis (in this process)."""

    def start() -> RunningServer:
        return start_server(Settings(environment="development", token=None, redis_url=redis_url))

    return start
