"""The agent's spawn step against the simulator's rosbridge, through the agent's rosbridge link."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import AsyncIterator, Callable

import httpx
import pytest

from app.protocol.events import AnyEvent, SpawnStep
from app.protocol.ros import RosFlavour
from app.server.config import Settings
from app.server.serve import RunningServer
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.events import EventLog
from vehicle_agent.robotlink import RosbridgeLink
from vehicle_agent.rosbridge_client import RosbridgeClient
from vehicle_agent.video import FixedPath, SyntheticVideo


def turtle1(server: RunningServer) -> dict[str, float]:
    """turtle1 as the simulator reports it over HTTP."""
    state = httpx.get(f"{server.url}/turtlesim/state").json()
    found: dict[str, float] = next(t for t in state["turtles"] if t["name"] == "turtle1")
    return found


@contextlib.asynccontextmanager
async def agent_on_rosbridge(
    server: RunningServer, spawn_step: bool, events: list[AnyEvent]
) -> AsyncIterator[Agent]:
    log = EventLog()
    log.listeners.append(events.append)
    rosbridge = server.url.replace("http", "ws", 1) + "/rosbridge"
    agent = Agent(
        AgentConfig(server=server.url, spawn_step=spawn_step),
        SyntheticVideo(160, 120, fps=5, path=FixedPath(0.5, 0.5)),
        RosbridgeLink(RosbridgeClient(rosbridge)),  # learns the robot's flavour from rosapi
        log,
    )
    task = asyncio.create_task(agent.run())
    try:
        async with asyncio.timeout(15):
            await agent.logged_in.wait()
        yield agent
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


@pytest.mark.parametrize("flavour", ["1", "2", "jazzy"])
async def test_agent_turns_the_turtle_up_at_start(
    start_server: Callable[[Settings], RunningServer], flavour: RosFlavour
) -> None:
    # teleport_absolute's type name differs in each flavour (turtlesim_msgs/srv/... in Jazzy).
    server = start_server(Settings(environment="development", token=None, ros=flavour))
    start = turtle1(server)
    assert start["theta"] == pytest.approx(0.0)
    events: list[AnyEvent] = []
    async with agent_on_rosbridge(server, True, events):
        async with asyncio.timeout(15):
            while not any(isinstance(e, SpawnStep) for e in events):
                await asyncio.sleep(0.05)
        spawn = next(e for e in events if isinstance(e, SpawnStep))
        assert spawn.ok is True, spawn
        after = turtle1(server)
    # Turned where it stood: facing up, not moved.
    assert after["theta"] == pytest.approx(math.pi / 2, abs=1e-6)
    assert (after["x"], after["y"]) == pytest.approx((start["x"], start["y"]), abs=1e-6)


async def test_spawn_step_can_be_switched_off(server: RunningServer) -> None:
    events: list[AnyEvent] = []
    async with agent_on_rosbridge(server, False, events) as agent:
        async with asyncio.timeout(15):
            while agent.pose is None:
                await asyncio.sleep(0.05)
        # Well past the moment the step would have been answered when switched on.
        await asyncio.sleep(1.0)
        after = turtle1(server)
    assert not any(isinstance(e, SpawnStep) for e in events)
    assert after["theta"] == pytest.approx(0.0)
