"""The whole system as a fleet: two instances on a real Redis, the aiortc vehicle agent on one,
the client page on the other, the relay from a relay pool. The pool is killed mid-flight; another
pool takes the room and piloting resumes without anyone pressing Start again. Run inside the
private network namespace::

    scripts/in-netns python3 -m pytest tests/fleet/test_fleet_e2e.py
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import signal
from collections.abc import Awaitable, Callable
from pathlib import Path

import httpx
import pytest
import redis.asyncio as aioredis
from playwright.async_api import async_playwright

from app.chromium import launch_options
from app.protocol.events import AnyEvent, GoalApplied, TwistSent
from app.relay.pool import RelayPool, room_members, start_pool_process
from app.server.fleet import keys
from app.server.serve import RunningServer
from tests.helpers.waiting import eventually
from tests.vehicle_agent.test_agent_pages import H, W, page_until
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.events import EventLog
from vehicle_agent.robotlink import SimLink
from vehicle_agent.video import FixedPath, SyntheticVideo

pytestmark = [pytest.mark.browser, pytest.mark.e2e, pytest.mark.slow]


async def test_fleet_pilots_across_instances_and_a_pool_takes_over_a_killed_pool(
    start_instance: Callable[[], RunningServer], redis_url: str, tmp_path: Path
) -> None:
    first, second = start_instance(), start_instance()
    redis = aioredis.Redis.from_url(redis_url, decode_responses=True)
    events: list[AnyEvent] = []
    log = EventLog()
    log.listeners.append(events.append)
    path = FixedPath(0.2, 0.42)  # the face on the left
    turtle = SimLink()
    agent = Agent(
        AgentConfig(server=first.url), SyntheticVideo(W, H, fps=15, path=path), turtle, log
    )
    agent_task = asyncio.create_task(agent.run())

    def heading() -> float:
        return math.degrees(turtle.sim.pose("turtle1").theta)

    def goals() -> int:
        return sum(isinstance(e, GoalApplied) for e in events)

    async def relay_holder() -> str | None:
        holder = await redis.get(keys.relay_lease("default"))
        return None if holder is None else str(holder)

    # The first pool is its own process, on the first instance, so that it can be SIGKILLed.
    pool_a = start_pool_process(first.url, redis_url, tmp_path / "pool-a.log")
    pool_b = RelayPool(second.url, redis_url, pool_id="pool-b")
    stop_b = asyncio.Event()
    pool_b_task: asyncio.Task[None] | None = None
    try:
        async with async_playwright() as pw:
            browser = await pw.chromium.launch(**launch_options())
            client = await browser.new_page()
            await client.goto(f"{second.url}/client?room=default&name=client&auto=1")

            # Pool A claims the room (it has a vehicle and no relay) and its page joins.
            async def relay_joined() -> bool:
                members = await room_members(redis, "default")
                return {"name": "relay", "role": "relay"} in members

            await _until(relay_joined, 90, "pool A's relay page to join the room")
            holder = await relay_holder()
            assert holder is not None and holder != "pool-b"

            await page_until(
                client,
                "() => !document.querySelector('[data-action=start]').disabled",
                60,
                "Start Piloting to be enabled on the client",
            )
            await client.get_by_role("button", name="Start Piloting").click()
            await eventually(lambda: 150 < heading() <= 180, 90, "the turtle to face left")

            # A second pool leaves a served room alone...
            pool_b_task = asyncio.create_task(pool_b.run(stop_b))
            await asyncio.sleep(3 * keys.TICK_S)
            assert pool_b.served == {} and await relay_holder() == holder

            # ...until the first pool is killed: the vehicle stops (goal timeout), the lease
            # runs out, pool B takes the room and the client's relay resumes piloting by itself.
            pool_a.send_signal(signal.SIGKILL)
            pool_a.wait(timeout=10)
            await eventually(
                lambda: any(isinstance(e, TwistSent) and e.seq is None for e in events[-50:]),
                10,
                "a zero Twist once the relay is gone",
            )
            path.x = 0.8  # the face moves right while nobody pilots
            await eventually(
                lambda: "default" in pool_b.served,
                keys.RELAY_LEASE_MS / 1000 + 10,
                "pool B to take the room over",
            )
            assert await relay_holder() == "pool-b"
            goals_before = goals()
            await eventually(lambda: goals() > goals_before + 5, 90, "goals from pool B's relay")
            await eventually(lambda: 0 < heading() < 30, 60, "the turtle to face right")
            assert await client.evaluate("() => window.autopilotStatus.wantPiloting") is True

            # The fleet page's table, from either instance, shows the room as pool B runs it.
            def fleet_row() -> dict[str, object]:
                table = httpx.get(f"{first.url}/fleet/rooms", timeout=10).json()
                row: dict[str, object] = next(r for r in table if r["room"] == "default")
                return row

            # The pool publishes once a tick, and pool B's page may still have been loading
            # OpenCV.js (piloting asked for, no operation yet) at its last report.
            def pool_b_piloting(row: dict[str, object]) -> bool:
                return row["pool"] == "pool-b" and row["piloting"] is True and bool(row["op"])

            await eventually(
                lambda: pool_b_piloting(fleet_row()),
                10,
                "the fleet table to show pool B piloting with an operation",
            )
            row = fleet_row()
            assert row["vehicles"] == ["vehicle"] and row["clients"] == ["client"], row
            assert row["relay"] == "relay", row
            await client.screenshot(path=str(tmp_path / "client.png"))
            await browser.close()
    finally:
        if pool_a.poll() is None:
            pool_a.kill()
            pool_a.wait(timeout=10)
        stop_b.set()
        if pool_b_task is not None:
            await asyncio.wait_for(pool_b_task, 30)
        agent_task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await agent_task
        await redis.aclose()


async def _until(condition: Callable[[], Awaitable[bool]], timeout: float, what: str) -> None:
    """Await the async ``condition`` until it is true."""
    try:
        async with asyncio.timeout(timeout):
            while not await condition():
                await asyncio.sleep(0.2)
    except TimeoutError:
        raise AssertionError(f"timed out after {timeout:g} s waiting for {what}") from None
