"""Access control across a fleet: room/role tokens, the login deadline and ``/fleet/rooms``.

With ``AUTOPILOT_SECRET`` set, every instance checks each login's token in the room owner's hub;
a socket logged in through another instance is not closed by its own instance's login deadline;
and an owner that takes a room over keeps members whose (checked, expiring) tokens have expired
since they logged in.
"""

from __future__ import annotations

import asyncio
import signal
import time
from collections.abc import Callable
from contextlib import AsyncExitStack
from typing import Any

import httpx
from websockets.asyncio.client import connect

from app.protocol import tokens
from app.relay.pool import RelayPool
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.fleet.conftest import ServeProcess
from tests.fleet.test_fleet_signaling import _until_roster
from tests.server.test_signaling_ws import Peer

SECRET = "fleet-test-secret-0123456789abcdef"
# Short enough that the tokens of the first logins have expired when the room is taken over.
SHORT_TTL_S = 2.0
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


async def test_tokens_deadline_and_takeover_with_expired_tokens(
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
        reply = await login(vehicle, "v", "vehicle", "a", token("a", "vehicle", SHORT_TTL_S))
        assert reply["success"] is True, reply
        # The owner checks logins coming through the other instance: no token, wrong room.
        stranger = await peer_on(second_url)
        for bad, why in ((None, "missing token"), (token("b", "client"), "room")):
            refused = await login(stranger, "c", "client", "a", bad)
            assert refused["success"] is False and why in refused["reason"], refused
            # Every refused message also gets an ``error``, as on one instance.
            assert (await stranger.recv())["type"] == "error"
        client = stranger
        reply = await login(client, "c", "client", "a", token("a", "client", SHORT_TTL_S))
        assert reply["success"] is True, reply
        assert (await vehicle.recv())["peers"] == [{"name": "c", "role": "client"}]

        # A socket that never logs in is closed by the deadline; the client, logged in through
        # the owner on the other instance, is not.
        idle = await peer_on(second_url)
        assert await idle.closed() == 1008

        await asyncio.sleep(SHORT_TTL_S + 0.5)  # both members' tokens have expired now
        first.send_signal(signal.SIGKILL)
        first.wait(timeout=10)
        # The survivor takes room "a" over, replaying the client's login despite its token.
        assert await _until_roster(client, []) == {"type": "leave", "from": "v"}

        again = await peer_on(second_url)
        reply = await login(again, "v", "vehicle", "a", token("a", "vehicle"))
        assert reply["success"] is True, reply
        assert reply["peers"] == [{"name": "c", "role": "client"}]
        assert (await client.recv())["peers"] == [{"name": "v", "role": "vehicle"}]
        await client.send({"type": "candidate", "to": "v", "candidate": None})
        assert await again.recv() == {
            "type": "candidate",
            "to": "v",
            "candidate": None,
            "from": "c",
        }


async def test_fleet_rooms_need_a_client_token_when_a_secret_is_set(
    redis_url: str, start_server: Callable[[Settings], RunningServer]
) -> None:
    server = start_server(Settings(environment="development", secret=SECRET, redis_url=redis_url))
    async with connect(server.ws_url) as ws:
        vehicle = Peer(ws)
        assert (await login(vehicle, "v", "vehicle", "r1", token("r1", "vehicle")))["success"]
        url = f"{server.url}/fleet/rooms"
        async with httpx.AsyncClient(timeout=10) as http:
            assert (await http.get(url)).status_code == 401
            for refused in (token("r1", "vehicle"), "not.a-token"):
                response = await http.get(url, headers={"Authorization": f"Bearer {refused}"})
                assert response.status_code == 401, response.text
            # A client token of any room, not only of the rooms listed.
            good = {"Authorization": f"Bearer {token('elsewhere', 'client')}"}
            response = await http.get(url, headers=good)
            assert response.status_code == 200, response.text
            assert [row["room"] for row in response.json()] == ["r1"]
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
