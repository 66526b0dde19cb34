"""The server's diffdrive robots, one per room, at most ``max_rooms`` at once: a further room is
refused while someone is connected to every robot, and gets one once a room is left empty."""

from __future__ import annotations

import asyncio

import pytest

from app.server.config import Settings
from app.server.rosbridge import RoomsFull, Simulator
from app.server.websocket import SocketPolicy


def simulator(max_rooms: int) -> Simulator:
    policy = SocketPolicy.from_settings(Settings(environment="development"))
    return Simulator(policy, robot="diffdrive", max_rooms=max_rooms)


def test_a_room_beyond_the_limit_waits_for_a_room_to_be_left() -> None:
    async def scenario() -> None:
        sim = simulator(max_rooms=2)
        try:
            in_a, _ = sim.open()
            in_b, _ = sim.open()
            sim.bind(in_a, "a")
            sim.bind(in_b, "b")
            in_c, _ = sim.open()
            with pytest.raises(RoomsFull):
                sim.bind(in_c, "c")
            # A second connection to a room that has its robot takes no new one.
            again_a, _ = sim.open()
            assert sim.bind(again_a, "a") is not None
            assert set(sim.rooms) == {"a", "b"}
            sim.forget(in_b)  # room b is empty now: its robot makes way
            sim.bind(in_c, "c")
            assert set(sim.rooms) == {"a", "c"}
            sim.forget(in_a)  # room a still has a connection: it keeps its robot
            with pytest.raises(RoomsFull):
                sim.bind(sim.open()[0], "d")
            assert set(sim.rooms) == {"a", "c"}
        finally:
            await sim.stop()

    asyncio.run(scenario())
