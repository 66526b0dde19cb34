"""The signaling rules through the real app: uvicorn on a free port, real WebSocket clients."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import AsyncExitStack
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import RunningServer
from app.server.signaling import Switchboard
from app.server.websocket import Shut, SocketPolicy
from app.signaling.hub import Hub, Outgoing

# Generous: the machine is shared and loaded; a healthy server answers in milliseconds.
TIMEOUT_S = 10


class Peer:
    """One real WebSocket connection to /ws, speaking JSON."""

    def __init__(self, ws: ClientConnection) -> None:
        self.ws = ws

    async def send(self, message: dict[str, Any] | str | bytes) -> None:
        await self.ws.send(json.dumps(message) if isinstance(message, dict) else message)

    async def recv(self) -> dict[str, Any]:
        message: dict[str, Any] = json.loads(await asyncio.wait_for(self.ws.recv(), TIMEOUT_S))
        return message

    async def login(self, name: str, role: str, room: str = "default") -> dict[str, Any]:
        await self.send({"type": "login", "name": name, "role": role, "room": room})
        return await self.recv()

    async def closed(self) -> int | None:
        """Wait until the server has closed the connection; its close code."""
        await asyncio.wait_for(self.ws.wait_closed(), TIMEOUT_S)
        return self.ws.close_code


Connect = Callable[[], Awaitable[Peer]]


async def open_peers(server: RunningServer) -> AsyncIterator[Connect]:
    async with AsyncExitStack() as stack:

        async def open_peer() -> Peer:
            return Peer(await stack.enter_async_context(connect(server.ws_url)))

        yield open_peer


@pytest.fixture
async def new_peer(server: RunningServer) -> AsyncIterator[Connect]:
    """Opens connections to the server; all closed after the test."""
    async for opener in open_peers(server):
        yield opener


async def joined(new_peer: Connect, name: str, role: str, room: str = "default") -> Peer:
    peer = await new_peer()
    reply = await peer.login(name, role, room)
    assert reply["success"] is True, reply
    return peer


async def test_login_reply_and_roster_updates(new_peer: Connect) -> None:
    relay = await new_peer()
    assert await relay.login("r", "relay", "lab") == {
        "type": "login",
        "success": True,
        "room": "lab",
        "peers": [],
        "iceServers": [],
        "iceTransportPolicy": "all",
    }
    vehicle = await new_peer()
    reply = await vehicle.login("v", "vehicle", "lab")
    assert reply["peers"] == [{"name": "r", "role": "relay"}]
    assert await relay.recv() == {
        "type": "peers",
        "room": "lab",
        "peers": [{"name": "v", "role": "vehicle"}],
    }


async def test_offer_answer_and_candidates_are_relayed_between_two_peers(
    new_peer: Connect,
) -> None:
    relay = await joined(new_peer, "r", "relay")
    vehicle = await joined(new_peer, "v", "vehicle")
    await relay.recv()  # roster update

    await vehicle.send({"type": "offer", "to": "r", "sdp": "v=0 offer", "from": "r"})
    assert await relay.recv() == {"type": "offer", "to": "r", "sdp": "v=0 offer", "from": "v"}

    await relay.send({"type": "answer", "to": "v", "sdp": "v=0 answer"})
    assert await vehicle.recv() == {"type": "answer", "to": "v", "sdp": "v=0 answer", "from": "r"}

    candidate = {"candidate": "candidate:1 1 udp 2122260223 10.203.0.1 5000 typ host"}
    await vehicle.send({"type": "candidate", "to": "r", "candidate": candidate})
    await relay.send({"type": "candidate", "to": "v", "candidate": None})
    assert (await relay.recv())["candidate"] == candidate
    assert await vehicle.recv() == {"type": "candidate", "to": "v", "candidate": None, "from": "r"}


async def test_client_commands_reach_the_relay(new_peer: Connect) -> None:
    relay = await joined(new_peer, "r", "relay")
    client = await joined(new_peer, "c", "client")
    await relay.recv()  # roster update
    for kind in ("getOps", "start", "stop"):
        await client.send({"type": kind})
        assert await relay.recv() == {"type": kind, "from": "c"}


# (payload, ref of the expected error, whether it comes from a fresh connection that sends it
# instead of logging in / as its login)
BAD_INPUT = {
    "malformed JSON": ("{oops", None, False),
    "non-object JSON": ("[1]", None, False),
    "unknown type": ({"type": "fly"}, "fly", False),
    "missing field": ({"type": "offer", "to": "r"}, "offer", False),
    "mistyped field": ({"type": "offer", "to": "r", "sdp": 1}, "offer", False),
    "wrong role": ({"type": "start"}, "start", False),
    "to naming nobody": ({"type": "offer", "to": "nobody", "sdp": "x"}, "offer", False),
    "binary frame": (b"\x00\x01", None, False),
    "before login": ({"type": "getOps"}, "getOps", True),
    "duplicate name": (
        {"type": "login", "name": "v", "role": "client", "room": "bad"},
        "login",
        True,
    ),
    "second relay": (
        {"type": "login", "name": "r2", "role": "relay", "room": "bad"},
        "login",
        True,
    ),
    "bad role": ({"type": "login", "name": "x", "role": "pilot", "room": "bad"}, "login", True),
}


@pytest.mark.parametrize("case", list(BAD_INPUT))
async def test_bad_input_gets_an_error_and_everyone_keeps_being_served(
    new_peer: Connect, case: str
) -> None:
    payload, ref, fresh = BAD_INPUT[case]
    relay = await joined(new_peer, "r", "relay", "bad")
    vehicle = await joined(new_peer, "v", "vehicle", "bad")
    other_relay = await joined(new_peer, "r", "relay", "good")
    other_client = await joined(new_peer, "c", "client", "good")
    await relay.recv()  # roster updates
    await other_relay.recv()

    sender = await new_peer() if fresh else vehicle
    await sender.send(payload)
    reply = await sender.recv()
    if ref == "login":
        assert reply["type"] == "login" and reply["success"] is False and reply["reason"]
        reply = await sender.recv()
    assert reply["type"] == "error" and reply["ref"] == ref and reply["reason"]

    # The offending connection still works...
    if fresh:
        assert (await sender.login("late", "client", "bad"))["success"] is True
        assert (await relay.recv())["type"] == "peers"
    await vehicle.send({"type": "offer", "to": "r", "sdp": "after"})
    # ...the next thing its room's relay sees is this offer: nothing stray came before it...
    assert await relay.recv() == {"type": "offer", "to": "r", "sdp": "after", "from": "v"}
    # ...and the other room never heard of any of it.
    await other_client.send({"type": "getOps"})
    assert await other_relay.recv() == {"type": "getOps", "from": "c"}


async def test_a_100_kib_frame_is_refused_before_it_is_buffered_and_others_carry_on(
    new_peer: Connect,
) -> None:
    relay = await joined(new_peer, "r", "relay")
    vehicle = await joined(new_peer, "v", "vehicle")
    client = await joined(new_peer, "c", "client")
    await relay.recv()  # roster updates
    await relay.recv()

    # uvicorn's ws_max_size (Settings.max_message_bytes) refuses the frame as it arrives.
    await client.send(json.dumps({"type": "offer", "to": "r", "sdp": "x" * 100 * 1024}))
    assert await client.closed() == 1009
    assert client.ws.close_reason == f"frame exceeds limit of {Settings().max_message_bytes} bytes"
    assert (await relay.recv())["type"] == "leave"
    await vehicle.send({"type": "offer", "to": "r", "sdp": "small"})
    assert (await relay.recv())["type"] == "peers"
    assert (await relay.recv())["sdp"] == "small"


async def test_closing_the_socket_counts_as_leave(new_peer: Connect) -> None:
    relay = await joined(new_peer, "r", "relay")
    vehicle = await joined(new_peer, "v", "vehicle")
    await relay.recv()  # roster update

    await vehicle.ws.close()
    assert await relay.recv() == {"type": "leave", "from": "v"}
    assert await relay.recv() == {"type": "peers", "room": "default", "peers": []}
    await joined(new_peer, "v", "vehicle")  # the name is free again


async def test_leave_is_relayed_then_the_server_closes_the_sender(new_peer: Connect) -> None:
    relay = await joined(new_peer, "r", "relay")
    client = await joined(new_peer, "c", "client")
    await relay.recv()  # roster update

    await relay.send({"type": "leave"})
    assert await client.recv() == {"type": "leave", "from": "r"}
    assert await relay.closed() == 1000
    # A relay coming back under the same name takes the free relay slot.
    await joined(new_peer, "r", "relay")
    assert (await client.recv())["peers"] == []  # after r left
    assert (await client.recv())["peers"] == [{"name": "r", "role": "relay"}]


async def test_an_abusive_peer_is_disconnected(new_peer: Connect) -> None:
    relay = await joined(new_peer, "r", "relay")
    vehicle = await joined(new_peer, "v", "vehicle")
    await relay.recv()  # roster update

    for _ in range(20):
        await vehicle.send("garbage")
    # Read the replies: the client stops reading the socket while its queue is full.
    with pytest.raises(ConnectionClosed):
        while True:
            assert (await vehicle.recv())["type"] == "error"
    assert vehicle.ws.close_code == 1008
    assert await relay.recv() == {"type": "leave", "from": "v"}


async def test_login_needs_the_token_when_the_server_has_one(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    secret = "signaling-ws-test-secret"
    server = start_server(Settings(secret=secret))
    token = tokens.sign(secret, "default", "client", now=time.time())
    async for new_peer in open_peers(server):
        peer = await new_peer()
        refused = await peer.login("c", "client")
        assert refused["success"] is False and "token" in refused["reason"]
        assert (await peer.recv())["ref"] == "login"
        await peer.send({"type": "login", "name": "c", "role": "client", "token": token})
        assert (await peer.recv())["success"] is True


async def test_a_peer_that_does_not_read_is_closed_instead_of_buffered_without_bound() -> None:
    board = Switchboard(Hub(), SocketPolicy(64 * 1024, outbox_messages=3, outbox_bytes=10**6))
    conn, outbox = board.open("127.0.0.1")
    board.dispatch([Outgoing(conn, {"type": "peers", "n": n}) for n in range(4)])

    # What was queued is dropped; what remains is the order to close the slow connection.
    assert len(outbox) == 0
    shut = await outbox.get()
    assert isinstance(shut, Shut) and shut.code == 1013
    board.dispatch([Outgoing(conn, {"type": "peers"})])
    assert len(outbox) == 0, "nothing is queued behind the close"
