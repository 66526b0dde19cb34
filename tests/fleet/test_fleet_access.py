"""Access control across a fleet: room/role tokens, the login deadline and ``/fleet/rooms``.

With ``AUTOPILOT_SECRET`` set, every instance checks each login's token in the room owner's hub;
a socket logged in through another instance is not closed by its own instance's login deadline;
and an owner that takes a room over keeps what each member's token grants, as renewed: a member
whose token expires is ended by whichever instance owns the room then.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import signal
import time
from collections.abc import Callable
from contextlib import AsyncExitStack
from typing import Any

import httpx
import pytest
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed

from app.protocol import tokens
from app.relay.pool import RelayPool
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.fleet.conftest import ServeProcess
from tests.server.test_signaling_ws import Peer

SECRET = "fleet-test-secret-0123456789abcdef"
# Long enough to outlive the logins and the kill, short enough to expire soon after a takeover.
SHORT_TTL_S = 6.0
LOGIN_TIMEOUT_S = 1.0
RELAY: tuple[tokens.Role, ...] = ("relay",)


def token(room: str, role: tokens.Role, ttl_s: float = 600.0) -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=ttl_s)


async def login(
    peer: Peer, name: str, role: tokens.Role, room: str, tok: str | None
) -> dict[str, Any]:
    message: dict[str, Any] = {"type": "login", "name": name, "role": role, "room": room}
    if tok is not None:
        message["token"] = tok
    await peer.send(message)
    return await peer.recv()


async def _until_closed(peer: Peer) -> list[dict[str, Any]]:
    """What the server sends ``peer`` until it closes the connection."""
    seen: list[dict[str, Any]] = []
    with contextlib.suppress(ConnectionClosed):
        while True:
            seen.append(json.loads(await asyncio.wait_for(peer.ws.recv(), SHORT_TTL_S + 15)))
    return seen


async def test_tokens_deadline_and_takeover_keep_what_each_token_grants(
    serve_process: ServeProcess,
) -> None:
    env = {"AUTOPILOT_SECRET": SECRET, "AUTOPILOT_LOGIN_TIMEOUT_S": str(LOGIN_TIMEOUT_S)}
    first_url, first = serve_process(env)
    second_url, _ = serve_process(env)
    ws = {url: url.replace("http", "ws", 1) + "/ws" for url in (first_url, second_url)}
    async with AsyncExitStack() as stack:

        async def peer_on(url: str) -> Peer:
            return Peer(await stack.enter_async_context(connect(ws[url])))

        # Room "a" is created through the instance that dies, so that one owns it.
        vehicle = await peer_on(first_url)
        reply = await login(vehicle, "v", "vehicle", "a", token("a", "vehicle"))
        assert reply["success"] is True, reply
        # The owner checks logins coming through the other instance: no token, wrong room.
        stranger = await peer_on(second_url)
        for bad, why in ((None, "missing token"), (token("b", "client"), "room")):
            refused = await login(stranger, "c", "client", "a", bad)
            assert refused["success"] is False and why in refused["reason"], refused
            # Every refused message also gets an ``error``, as on one instance.
            assert (await stranger.recv())["type"] == "error"
        lapsing = stranger
        reply = await login(lapsing, "c", "client", "a", token("a", "client", SHORT_TTL_S))
        assert reply["success"] is True, reply
        assert (await vehicle.recv())["peers"] == [{"name": "c", "role": "client"}]
        # A second client renews through the instance that is not the owner, with a token of
        # its own that lasts: the owner keeps that in the room's member list.
        renewing = await peer_on(second_url)
        reply = await login(renewing, "d", "client", "a", token("a", "client", SHORT_TTL_S))
        assert reply["success"] is True, reply
        lasting = token("a", "client")
        await renewing.send({"type": "renew", "token": lasting})
        assert await renewing.recv() == {
            "type": "renewed",
            "token": lasting,
            "renewIn": pytest.approx(300, abs=2),
        }

        # A socket that never logs in is closed by the deadline; the clients, logged in through
        # the owner on the other instance, are not.
        idle = await peer_on(second_url)
        assert await idle.closed() == 1008

        first.send_signal(signal.SIGKILL)
        first.wait(timeout=10)
        # The survivor takes room "a" over with each member's claims: the client whose token
        # expires is ended (the instance that admitted it is dead), the renewed one stays.
        last = await _until_closed(lapsing)
        assert lapsing.ws.close_code == 1008 and lapsing.ws.close_reason == "token expired"
        assert "token expired" in last[-1]["reason"]
        seen = [await renewing.recv() for _ in range(4)]
        assert {"type": "leave", "from": "v"} in seen and {"type": "leave", "from": "c"} in seen
        again = await peer_on(second_url)
        reply = await login(again, "v", "vehicle", "a", token("a", "vehicle"))
        assert reply["success"] is True, reply
        assert reply["peers"] == [{"name": "d", "role": "client"}]
        assert (await renewing.recv())["peers"] == [{"name": "v", "role": "vehicle"}]
        await renewing.send({"type": "candidate", "to": "v", "candidate": None})
        assert await again.recv() == {
            "type": "candidate",
            "to": "v",
            "candidate": None,
            "from": "d",
        }


async def test_fleet_rooms_show_a_room_token_its_room_and_a_fleet_token_every_room(
    redis_url: str, start_server: Callable[[Settings], RunningServer]
) -> None:
    server = start_server(Settings(environment="development", secret=SECRET, redis_url=redis_url))
    async with connect(server.ws_url) as one, connect(server.ws_url) as two:
        for ws, name, room in ((one, "v1", "r1"), (two, "v2", "r2")):
            reply = await login(Peer(ws), name, "vehicle", room, token(room, "vehicle"))
            assert reply["success"], reply
        url = f"{server.url}/fleet/rooms"

        async def seen(tok: str | None) -> tuple[int, Any]:
            headers = {} if tok is None else {"Authorization": f"Bearer {tok}"}
            response = await http.get(url, headers=headers)
            return response.status_code, response.json()

        async with httpx.AsyncClient(timeout=10) as http:
            assert (await seen(None))[0] == 401
            assert (await seen("not.a-token"))[0] == 401
            # A room's token, of any role, sees that room alone (issue 37.7).
            for role in ("vehicle", "relay", "client"):
                status, rows = await seen(token("r2", role))  # type: ignore[arg-type]
                assert status == 200 and [(r["room"], r["vehicles"]) for r in rows] == [
                    ("r2", ["v2"])
                ]
            assert await seen(token("elsewhere", "client")) == (200, [])
            fleet = tokens.sign(SECRET, tokens.ALL_ROOMS, "fleet", now=time.time(), ttl_s=60)
            status, rows = await seen(fleet)
            assert status == 200 and [r["room"] for r in rows] == ["r1", "r2"]
            # The page holds no data: it loads, and asks for its rows with the fragment's token.
            assert (await http.get(f"{server.url}/fleet")).status_code == 200


def test_the_pool_mints_a_relay_token_per_room(redis_url: str) -> None:
    pool = RelayPool("http://127.0.0.1:1", redis_url, secret=SECRET)
    for room in ("a", "b"):
        minted = pool.room_token(room)
        assert minted is not None
        claims = tokens.verify(SECRET, minted, now=time.time(), room=room, roles=RELAY)
        assert claims.role == "relay"
    assert RelayPool("http://127.0.0.1:1", redis_url, token="given").room_token("a") == "given"
    assert RelayPool("http://127.0.0.1:1", redis_url).room_token("a") is None
