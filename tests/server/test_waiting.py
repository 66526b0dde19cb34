"""Connections without a token against the real server: they have a deadline on both routes,
hold only their own budget of places (never a logged-in peer's, nor a newcomer's), and sockets
the server closed or half-sent requests are dropped rather than held."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import CLOSE_ABORT_S, RunningServer
from app.server.websocket import CLOSE_GRACE_S, MAKE_WAY
from tests.helpers.sockets import TIMEOUT_S, StuckClient, recv, rosbridge_url

SECRET = "waiting-test-secret-0123456789"
ROOM = "w"


def token(role: tokens.Role) -> str:
    return tokens.sign(SECRET, ROOM, role, now=time.time(), ttl_s=600)


async def closed(ws: ClientConnection) -> tuple[int | None, str | None]:
    """Read (and drop) what is left until the server's close; its code and reason."""
    with contextlib.suppress(ConnectionClosed):
        async with asyncio.timeout(TIMEOUT_S):
            async for _ in ws:
                pass
    return ws.close_code, ws.close_reason


async def log_in(server: RunningServer, name: str, role: tokens.Role) -> ClientConnection:
    ws = await connect(server.ws_url)
    login = {"type": "login", "name": name, "role": role, "room": ROOM, "token": token(role)}
    await ws.send(json.dumps(login))
    reply = await recv(ws)
    assert reply["type"] == "login" and reply["success"] is True, reply
    return ws


async def drive(server: RunningServer) -> dict[str, Any]:
    """A vehicle's rosbridge session: auth, then a call only a vehicle token may make."""
    async with connect(rosbridge_url(server)) as ws:
        await ws.send(json.dumps({"op": "auth", "token": token("vehicle")}))
        await ws.send(json.dumps({"op": "call_service", "service": "/clear", "id": "c"}))
        return await recv(ws)


def stuck_clients(url: str, count: int) -> list[StuckClient]:
    return [StuckClient(url) for _ in range(count)]


def app_state(server: RunningServer) -> Any:
    return server.server.config.app.state


async def test_rosbridge_closes_a_connection_without_a_token_at_the_login_deadline(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    server = start_server(Settings(secret=SECRET, login_timeout_s=0.5))
    async with connect(rosbridge_url(server)) as idle, connect(server.ws_url) as idle_ws:
        vehicle = await drive(server)  # shown a token: not closed
        assert vehicle["op"] == "service_response" and vehicle["result"] is True
        started = time.monotonic()
        # One setting, one deadline: the same on both routes.
        assert await closed(idle) == (1008, "no auth within 0.5 s")
        assert await closed(idle_ws) == (1008, "no login within 0.5 s")
        assert time.monotonic() - started < TIMEOUT_S / 2


async def test_rosbridge_sockets_without_a_token_never_keep_the_vehicle_out(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    server = start_server(Settings(secret=SECRET, max_rosbridge_sessions=4))
    idle = await asyncio.to_thread(stuck_clients, rosbridge_url(server), 10)
    try:
        outboxes = app_state(server).simulator.outboxes
        assert outboxes.waiting <= Settings().max_waiting_per_address
        reply = await drive(server)
        assert reply["op"] == "service_response" and reply["result"] is True
    finally:
        for client in idle:
            client.close()


async def test_a_login_gets_in_while_300_sockets_without_a_token_from_one_address_are_open(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    settings = Settings(secret=SECRET)
    server = start_server(settings)
    idle = await asyncio.to_thread(stuck_clients, server.ws_url, 300)
    try:
        board = app_state(server).signaling
        # The address holds its budget of places and no more: the rest made way, oldest first.
        assert board.outboxes.waiting == settings.max_waiting_per_address
        assert len(board.outboxes) < settings.max_connections
        ws = await log_in(server, "c", "client")
        await ws.close()
    finally:
        for client in idle:
            client.close()


async def test_a_newcomer_takes_the_place_of_the_oldest_waiting_connection(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    server = start_server(Settings(secret=SECRET, max_connections=3))
    async with connect(server.ws_url) as oldest, connect(server.ws_url) as waiting:
        relay = await log_in(server, "r", "relay")
        async with connect(server.ws_url) as newcomer:
            assert await closed(oldest) == (1013, MAKE_WAY)
            login = {"type": "login", "name": "c", "role": "client", "room": ROOM}
            await newcomer.send(json.dumps(login | {"token": token("client")}))
            assert (await recv(newcomer))["success"] is True
            # The logged-in peers never make way, and the younger waiting one kept its place.
            await asyncio.wait_for(await relay.ping(), TIMEOUT_S)
            await asyncio.wait_for(await waiting.ping(), TIMEOUT_S)
        await relay.close()


async def test_connections_are_capped_with_a_clear_close_once_every_place_is_logged_in(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    server = start_server(Settings(secret=SECRET, max_connections=2))
    first, second = await log_in(server, "r", "relay"), await log_in(server, "c", "client")
    async with connect(server.ws_url) as extra:
        assert await closed(extra) == (1013, "server full: 2 connections")
    await first.close()
    await second.close()


def server_connections(server: RunningServer) -> int:
    return len(server.server.server_state.connections)


async def test_a_close_the_peer_never_answers_aborts_the_connection(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    server = start_server(Settings())
    stuck = await asyncio.to_thread(StuckClient, rosbridge_url(server))
    try:
        # Requests with big replies it never reads fill every buffer on the way to it ...
        big = {"op": "call_service", "service": "/rosapi/topics", "id": "x" * 50_000}
        for _ in range(4):
            assert await asyncio.to_thread(stuck.send, json.dumps(big))
        # ... then a frame over the limit: the server closes (1009), and its close frame waits
        # behind replies the peer will never read.
        await asyncio.to_thread(stuck.send, "x" * (Settings().max_message_bytes + 1))
        started = time.monotonic()
        bound = CLOSE_GRACE_S + CLOSE_ABORT_S + 2.0
        while server_connections(server) > 0:
            assert time.monotonic() - started < bound, "the closed socket is still held"
            await asyncio.sleep(0.1)
        # The peer sees its connection reset: nothing of it is left on the server.
        stuck.sock.settimeout(TIMEOUT_S)
        with pytest.raises(ConnectionResetError):
            while stuck.sock.recv(65536):
                pass
    finally:
        stuck.close()


def test_half_sent_request_headers_are_dropped(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    server = start_server(Settings(header_timeout_s=0.5))
    port = int(server.url.rsplit(":", 1)[1])
    with socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S) as slow:
        slow.sendall(b"GET /healthz HTTP/1.1\r\nHost: 127.0.0.1\r\n")
        started = time.monotonic()
        with contextlib.suppress(ConnectionResetError):
            assert slow.recv(1024) == b""  # dropped, with no answer
        assert time.monotonic() - started < TIMEOUT_S / 2
    # Headers that arrive in pieces but in time are answered.
    with socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S) as prompt:
        prompt.sendall(b"GET /healthz HTTP/1.1\r\n")
        time.sleep(0.2)
        prompt.sendall(b"Host: 127.0.0.1\r\nConnection: close\r\n\r\n")
        assert prompt.recv(1024).startswith(b"HTTP/1.1 200")


class Flood:
    """Sockets without a token opened to each URL in turn, over and over, from a thread, until
    the ``with`` block ends (at most ``limit`` at once: the oldest are closed first)."""

    def __init__(self, urls: list[str], limit: int = 200) -> None:
        self.urls, self.limit, self.opened = urls, limit, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="flood", daemon=True)

    def __enter__(self) -> Flood:
        self._thread.start()
        return self

    def __exit__(self, *_: object) -> None:
        self._stop.set()
        self._thread.join(TIMEOUT_S)

    def _run(self) -> None:
        open_: list[StuckClient] = []
        try:
            while not self._stop.is_set():
                with contextlib.suppress(OSError, InvalidStatus):
                    open_.append(StuckClient(self.urls[self.opened % len(self.urls)]))
                    self.opened += 1
                if len(open_) > self.limit:
                    open_.pop(0).close()
        finally:
            for client in open_:
                client.close()


@contextlib.contextmanager
def flooding(server: RunningServer) -> Iterator[Flood]:
    with Flood([server.ws_url, rosbridge_url(server)]) as flood:
        while flood.opened < 100:  # under way before anyone logs in
            time.sleep(0.05)
        yield flood


async def test_a_vehicle_relay_and_client_get_in_during_a_flood_without_tokens(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    server = start_server(Settings(secret=SECRET))
    with flooding(server) as flood:
        peers = [await log_in(server, name, role) for name, role in _ROLES]
        reply = await drive(server)
        assert reply["op"] == "service_response" and reply["result"] is True
        for ws in peers:
            await ws.close()
        assert flood.opened > 100


_ROLES: list[tuple[str, tokens.Role]] = [("v", "vehicle"), ("r", "relay"), ("c", "client")]
