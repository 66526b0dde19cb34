"""A relay pool on a real Redis: it serves a room that has a vehicle, and brings the room's relay
back when its Chromium is killed."""

from __future__ import annotations

import asyncio
import os
import signal
from collections.abc import Awaitable, Callable
from contextlib import AsyncExitStack

import pytest
from websockets.asyncio.client import connect

from app.relay.metrics import RelayMetrics
from app.relay.pool import RelayPool, room_members
from app.server.serve import RunningServer
from tests.helpers.processes import browser_processes
from tests.helpers.waiting import eventually
from tests.server.test_signaling_ws import Peer, joined

pytestmark = [pytest.mark.browser, pytest.mark.slow]

RELAY = {"name": "relay", "role": "relay"}


async def test_the_pool_serves_a_vehicle_s_room_and_survives_its_browser_dying(
    start_instance: Callable[[], RunningServer], redis_url: str
) -> None:
    server = start_instance()
    before = browser_processes()
    pool = RelayPool(server.url, redis_url, pool_id="pool-a")
    stop = asyncio.Event()
    task = asyncio.create_task(pool.run(stop))
    try:
        async with AsyncExitStack() as stack:

            async def new_peer() -> Peer:
                return Peer(await stack.enter_async_context(connect(server.ws_url)))

            vehicle = await joined(new_peer, "vehicle", "vehicle", "lab")

            async def relay_in_room() -> bool:
                return RELAY in await room_members(pool.redis, "lab")

            async def until(condition: Callable[[], Awaitable[bool]], what: str) -> None:
                try:
                    async with asyncio.timeout(90):
                        while not await condition():
                            await asyncio.sleep(0.2)
                except TimeoutError:
                    raise AssertionError(f"timed out after 90 s waiting for {what}") from None

            await until(relay_in_room, "the pool's relay to join the room")
            # The page joins the room before the pool's open() returns and records it as served.
            await eventually(lambda: list(pool.served) == ["lab"], 10, "the pool to record it")
            # The metrics' poll reads the page (loaded: it joined), not piloting.
            metrics = RelayMetrics()
            await metrics.poll_once(pool.pages())
            assert metrics.registry.get_sample_value("autopilot_relay_pages") == 1
            assert metrics.registry.get_sample_value("autopilot_relay_piloting") == 0
            ours = browser_processes() - before
            assert len(ours) == 1
            os.kill(ours.pop(), signal.SIGKILL)
            message = await vehicle.recv()
            while message["type"] != "leave":
                message = await vehicle.recv()
            assert message == {"type": "leave", "from": "relay"}
            await until(relay_in_room, "the relay to come back in a new browser")
            await eventually(lambda: list(pool.served) == ["lab"], 10, "the room still served")

            # The new page, in the new browser (the pool lists it once its open() returns).
            async def new_page_answers() -> bool:
                await metrics.poll_once(pool.pages())
                return metrics.registry.get_sample_value("autopilot_relay_pages") == 1

            await until(new_page_answers, "the metrics' poll to read the new page")
    finally:
        stop.set()
        await asyncio.wait_for(task, 30)
