"""``/fleet`` lists the rooms of every instance and follows them live, in a real browser."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from contextlib import AsyncExitStack

import httpx
import pytest
from playwright.async_api import Browser, Page, async_playwright
from websockets.asyncio.client import connect

from app.chromium import launch_options
from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.server.test_signaling_ws import Peer, joined

pytestmark = [pytest.mark.browser]


async def launch(stack: AsyncExitStack) -> Browser:
    """Headless Chromium, closed (with Playwright) when ``stack`` closes."""
    pw = await stack.enter_async_context(async_playwright())
    browser = await pw.chromium.launch(**launch_options())
    stack.push_async_callback(browser.close)
    return browser


async def rows(page: Page) -> list[list[str]]:
    """The table's cells, one list per room row."""
    cells: list[list[str]] = await page.evaluate(
        """() => [...document.querySelectorAll('[data-testid=fleet-rows] tr')]
             .map((tr) => [...tr.children].map((td) => td.textContent))"""
    )
    return cells


async def until_rows(page: Page, expected: list[list[str]], what: str) -> None:
    """Wait until the first five columns (room, vehicle, relay, pool, clients) match."""
    try:
        async with asyncio.timeout(20):
            while [row[:5] for row in await rows(page)] != expected:
                await asyncio.sleep(0.2)
    except TimeoutError:
        raise AssertionError(f"{what}: the page shows {await rows(page)}") from None


async def test_the_fleet_page_lists_rooms_of_every_instance_live(
    start_instance: Callable[[], RunningServer],
) -> None:
    first, second = start_instance(), start_instance()
    async with AsyncExitStack() as stack:

        async def peer_on(server: RunningServer) -> Peer:
            return Peer(await stack.enter_async_context(connect(server.ws_url)))

        browser = await launch(stack)
        page = await browser.new_page()
        await page.goto(f"{second.url}/fleet")
        await until_rows(page, [], "no rooms at first")

        vehicle = await joined(lambda: peer_on(first), "robot-1", "vehicle", "lab")
        await until_rows(page, [["lab", "robot-1", "–", "–", "–"]], "the vehicle's room")
        await joined(lambda: peer_on(second), "alice", "client", "lab")
        await joined(lambda: peer_on(second), "robot-2", "vehicle", "yard")
        await until_rows(
            page,
            [["lab", "robot-1", "–", "–", "alice"], ["yard", "robot-2", "–", "–", "–"]],
            "a client joined and a second room",
        )
        link = await page.get_attribute("tr[data-room=lab] a", "href")
        assert link == "/client?room=lab&name=client"

        await vehicle.send({"type": "leave"})
        await until_rows(
            page,
            [["lab", "–", "–", "–", "alice"], ["yard", "robot-2", "–", "–", "–"]],
            "the vehicle left",
        )


async def test_without_redis_the_fleet_is_this_process_s_rooms(server: RunningServer) -> None:
    async with connect(server.ws_url) as ws:
        peer = Peer(ws)
        assert (await peer.login("robot", "vehicle", "solo"))["success"]
        table = httpx.get(f"{server.url}/fleet/rooms", timeout=10).json()
    assert [(row["room"], row["vehicles"], row["piloting"]) for row in table] == [
        ("solo", ["robot"], None)
    ]


async def test_with_a_secret_the_page_sends_the_token_of_its_fragment(
    redis_url: str, start_server: Callable[[Settings], RunningServer]
) -> None:
    secret = "fleet-page-secret-0123456789abcdef"
    server = start_server(Settings(environment="development", secret=secret, redis_url=redis_url))

    def token(room: str, role: tokens.TokenRole) -> str:
        return tokens.sign(secret, room, role, now=time.time())

    async with AsyncExitStack() as stack:
        for name, room in (("robot", "lab"), ("mower", "yard")):
            vehicle = Peer(await stack.enter_async_context(connect(server.ws_url)))
            await vehicle.send(
                {"type": "login", "name": name, "role": "vehicle", "room": room}
                | {"token": token(room, "vehicle")}
            )
            assert (await vehicle.recv())["success"] is True
        browser = await launch(stack)
        page = await browser.new_page()
        # Without a token the page loads but gets no rows, and says why.
        await page.goto(f"{server.url}/fleet")
        state = page.get_by_test_id("fleet-state")
        await state.filter(has_text="a token is needed").wait_for(timeout=20_000)
        assert await rows(page) == []
        # A room's token shows that room; a fleet token every room.
        mine = await browser.new_page()
        await mine.goto(f"{server.url}/fleet#token={token('yard', 'client')}")
        await until_rows(mine, [["yard", "mower", "–", "–", "–"]], "the room of the token")
        every = await browser.new_page()
        await every.goto(f"{server.url}/fleet#token={token(tokens.ALL_ROOMS, 'fleet')}")
        await until_rows(
            every,
            [["lab", "robot", "–", "–", "–"], ["yard", "mower", "–", "–", "–"]],
            "every room with the fleet token",
        )
