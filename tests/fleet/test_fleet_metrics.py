"""The server's metrics in a fleet: each room is counted once, by the instance that owns it,
whichever instance its peers' sockets are on; frames are counted where the room's hub reads them."""

from __future__ import annotations

import json
from collections.abc import Callable

from websockets.asyncio.client import connect

from app.server.serve import RunningServer
from tests.helpers.sockets import recv
from tests.helpers.waiting import eventually


def gauge(server: RunningServer, name: str, **labels: str) -> float:
    return server.metrics.registry.get_sample_value(name, labels) or 0.0


async def test_a_room_with_peers_on_two_instances_is_counted_once(
    start_instance: Callable[[], RunningServer],
) -> None:
    first, second = start_instance(), start_instance()
    async with connect(first.ws_url) as vehicle, connect(second.ws_url) as client:
        for ws, name, role in ((vehicle, "v", "vehicle"), (client, "c", "client")):
            await ws.send(json.dumps({"type": "login", "name": name, "role": role, "room": "f"}))
            assert (await recv(ws))["success"] is True
        await client.send(json.dumps({"type": "hello"}))
        assert (await recv(client))["type"] == "error"

        def counted_once() -> bool:
            return (
                sum(gauge(s, "autopilot_rooms") for s in (first, second)) == 1
                and sum(gauge(s, "autopilot_peers", role="vehicle") for s in (first, second)) == 1
                and sum(gauge(s, "autopilot_peers", role="client") for s in (first, second)) == 1
            )

        await eventually(counted_once, timeout=5, what="the room counted once in the fleet")
    total = sum(
        gauge(s, "autopilot_signaling_messages_total", type=kind)
        for s in (first, second)
        for kind in ("login", "other")
    )
    assert total == 3  # two logins and the unknown type, each read once in the fleet
    refused = sum(gauge(s, "autopilot_refusals_total", reason="invalid") for s in (first, second))
    assert refused == 1
