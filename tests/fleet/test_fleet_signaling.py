"""Signaling across two instances on a real Redis behaves exactly as on one instance.

The single-instance WebSocket tests run again here, unchanged, with each new peer connected to
the next instance in turn, so every room of theirs has peers on both. Then what only a fleet
has: an instance killed with SIGKILL, its peers dropped from rosters elsewhere.
"""

from __future__ import annotations

import asyncio
import json
import signal
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack

import pytest
from websockets.asyncio.client import connect

from app.server.fleet import keys
from app.server.serve import RunningServer
from tests.fleet.conftest import ServeProcess
from tests.server.test_signaling_ws import (
    Connect,
    Peer,
    joined,
    test_a_100_kib_frame_is_refused_before_it_is_buffered_and_others_carry_on,
    test_an_abusive_peer_is_disconnected,
    test_bad_input_gets_an_error_and_everyone_keeps_being_served,
    test_client_commands_reach_the_relay,
    test_closing_the_socket_counts_as_leave,
    test_leave_is_relayed_then_the_server_closes_the_sender,
    test_login_reply_and_roster_updates,
    test_offer_answer_and_candidates_are_relayed_between_two_peers,
)

# The single-instance tests, collected again in this module with the two-instance ``new_peer``.
__all__ = [
    "test_a_100_kib_frame_is_refused_before_it_is_buffered_and_others_carry_on",
    "test_an_abusive_peer_is_disconnected",
    "test_bad_input_gets_an_error_and_everyone_keeps_being_served",
    "test_client_commands_reach_the_relay",
    "test_closing_the_socket_counts_as_leave",
    "test_leave_is_relayed_then_the_server_closes_the_sender",
    "test_login_reply_and_roster_updates",
    "test_offer_answer_and_candidates_are_relayed_between_two_peers",
]


@pytest.fixture
async def new_peer(start_instance: Callable[[], RunningServer]) -> AsyncIterator[Connect]:
    """Opens connections alternately to two instances of one service."""
    instances = [start_instance(), start_instance()]
    async with AsyncExitStack() as stack:
        opened = 0

        async def open_peer() -> Peer:
            nonlocal opened
            server = instances[opened % 2]
            opened += 1
            return Peer(await stack.enter_async_context(connect(server.ws_url)))

        yield open_peer


async def test_a_killed_instance_s_peers_leave_their_rooms_everywhere_else(
    serve_process: ServeProcess,
) -> None:
    first_url, first = serve_process()
    second_url, _ = serve_process()
    ws = {url: url.replace("http", "ws", 1) + "/ws" for url in (first_url, second_url)}
    async with AsyncExitStack() as stack:

        async def peer_on(url: str) -> Peer:
            return Peer(await stack.enter_async_context(connect(ws[url])))

        # Room "a" is created from the instance that dies (it owns it); room "b" from the other.
        vehicle_a = await joined(lambda: peer_on(first_url), "v", "vehicle", "a")
        client_a = await joined(lambda: peer_on(second_url), "c", "client", "a")
        client_b = await joined(lambda: peer_on(second_url), "c", "client", "b")
        vehicle_b = await joined(lambda: peer_on(first_url), "v", "vehicle", "b")
        assert (await vehicle_a.recv())["peers"] == [{"name": "c", "role": "client"}]
        assert (await client_b.recv())["peers"] == [{"name": "v", "role": "vehicle"}]
        del vehicle_b

        first.send_signal(signal.SIGKILL)
        first.wait(timeout=10)
        loop = asyncio.get_running_loop()
        killed_at = loop.time()
        # Room "b" (owned by the survivor) and room "a" (taken over by it) both hear it.
        for survivor in (client_a, client_b):
            assert await _until_roster(survivor, []) == {"type": "leave", "from": "v"}
        told_within = loop.time() - killed_at
        # The bound is the design's (heartbeat TTL + one tick), not a timing target.
        assert told_within < (keys.INSTANCE_TTL_MS / 1000 + keys.TICK_S) + 2

        # The vehicle comes back through the surviving instance; the room goes on.
        again = await joined(lambda: peer_on(second_url), "v", "vehicle", "a")
        assert (await client_a.recv())["peers"] == [{"name": "v", "role": "vehicle"}]
        await client_a.send({"type": "candidate", "to": "v", "candidate": None})
        expected = {"type": "candidate", "to": "v", "candidate": None, "from": "c"}
        assert await again.recv() == expected


async def _until_roster(peer: Peer, roster: list[dict[str, str]]) -> dict[str, object]:
    """Read until a ``leave``, then the roster that follows it; returns the ``leave``."""
    left = await asyncio.wait_for(peer.ws.recv(), 15)
    message = json.loads(left)
    assert message["type"] == "leave", message
    update = await peer.recv()
    assert update == {"type": "peers", "room": update["room"], "peers": roster}
    return dict(message)
