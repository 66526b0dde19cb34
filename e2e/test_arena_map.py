"""The client page of a diffdrive server draws the simulated arena: its proportions, the
billboards where the arena's state puts them, the walker moving as its robot's arena runs."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Iterator
from typing import Any

import pytest
import websockets
from playwright.sync_api import Browser, Page

from app.diffdrive.arena import ARENA, FLAME_AT
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from tests.helpers.sockets import rosbridge_url
from tests.helpers.waiting import wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

ROOM_NAME = "map-room"
WAIT_S = 15.0
# The colour arenaview.js draws the flame's centre in.
FLAME = (0xFF, 0x7A, 0x1A)


@pytest.fixture(scope="module")
def diffdrive() -> Iterator[RunningServer]:
    running = start_in_thread(Settings(environment="development", robot="diffdrive"))
    yield running
    running.stop()


@pytest.fixture(scope="module")
def robot_running(diffdrive: RunningServer) -> Iterator[None]:
    """A rosbridge client in the room, so that the room has its robot and its arena's clock runs."""
    stop = threading.Event()

    async def hold() -> None:
        url = f"{rosbridge_url(diffdrive)}?room={ROOM_NAME}"
        async with websockets.connect(url) as ws:
            await ws.send(json.dumps({"op": "subscribe", "topic": "/odom", "throttle_rate": 500}))
            while not stop.is_set():
                try:
                    await asyncio.wait_for(ws.recv(), 0.2)
                except TimeoutError:
                    pass

    thread = threading.Thread(target=lambda: asyncio.run(hold()), daemon=True)
    thread.start()
    yield
    stop.set()
    thread.join(timeout=5)


@pytest.fixture
def client(browser: Browser, diffdrive: RunningServer, robot_running: None) -> Iterator[Page]:
    page = browser.new_page()
    page.goto(f"{diffdrive.url}/client?room={ROOM_NAME}")
    yield page
    page.close()


def billboards(page: Page) -> dict[str, Any]:
    found: dict[str, Any] = page.evaluate("() => window.autopilotStatus?.billboards ?? null")
    return found


def pixel(page: Page, x: float, y: float) -> tuple[int, int, int]:
    """The map canvas's colour at arena point (x, y)."""
    rgb: list[int] = page.evaluate(
        """([x, y, width]) => {
            const canvas = document.querySelector('[data-testid="turtle-view"]');
            const scale = canvas.width / width;
            const data = canvas.getContext('2d')
                .getImageData(Math.round(x * scale), Math.round(canvas.height - y * scale), 1, 1)
                .data;
            return [data[0], data[1], data[2]];
        }""",
        [x, y, ARENA.width],
    )
    return rgb[0], rgb[1], rgb[2]


def test_the_map_has_the_arenas_proportions_and_its_billboards(client: Page) -> None:
    wait_until(lambda: billboards(client) is not None, WAIT_S, "the arena's billboards on the map")
    width, height = client.evaluate(
        """() => {
            const canvas = document.querySelector('[data-testid="turtle-view"]');
            return [canvas.width, canvas.height];
        }"""
    )
    assert height / width == pytest.approx(ARENA.depth / ARENA.width, abs=0.01)
    assert set(billboards(client)) == {b.name for b in ARENA.billboards}
    assert pixel(client, *FLAME_AT) == FLAME


def test_the_walker_moves_on_the_map_as_the_arena_runs(client: Page) -> None:
    wait_until(lambda: billboards(client) is not None, WAIT_S, "the arena's billboards on the map")
    first = billboards(client)["walker"]
    wait_until(
        lambda: (
            abs(billboards(client)["walker"]["x"] - first["x"]) > 0.1
            or abs(billboards(client)["walker"]["y"] - first["y"]) > 0.1
        ),
        WAIT_S,
        "the walker moving on the map",
    )
