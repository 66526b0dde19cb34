"""Issue 37.4 against the real server: a session ends when its token expires, unless it renews
in-band -- ``renew`` on ``/ws`` (the server answers with a fresh token), the ``auth`` op again on
``/rosbridge``."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.helpers.sockets import TIMEOUT_S, recv, rosbridge_url

SECRET = "token-expiry-test-secret"
# Short enough that a test outlives several of them, long enough for a login on a loaded machine.
LIFETIME_S = 3.0


def _token(role: tokens.Role, ttl_s: float, room: str = "lab") -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=ttl_s)


@pytest.fixture
def guarded(start_server: Callable[[Settings], RunningServer]) -> RunningServer:
    return start_server(Settings(environment="development", secret=SECRET))


async def _login(ws: ClientConnection, name: str, role: tokens.Role, token: str) -> dict[str, Any]:
    message = {"type": "login", "name": name, "role": role, "room": "lab", "token": token}
    await ws.send(json.dumps(message))
    reply = await recv(ws)
    assert reply["success"] is True, reply
    return reply


async def _until_closed(ws: ClientConnection, seconds: float) -> list[dict[str, Any]]:
    """Everything the server sends until it closes the connection (within ``seconds``)."""
    seen: list[dict[str, Any]] = []

    async def read() -> None:
        try:
            async for text in ws:
                seen.append(json.loads(text))
        except ConnectionClosed:
            return

    await asyncio.wait_for(read(), seconds)
    return seen


async def test_a_relay_whose_token_expires_leaves_the_room_and_receives_no_more(
    guarded: RunningServer,
) -> None:
    # Issue 37.4: a relay whose token had expired stayed in the room and kept receiving.
    async with connect(guarded.ws_url) as relay, connect(guarded.ws_url) as vehicle:
        await _login(relay, "r", "relay", _token("relay", LIFETIME_S))
        await _login(vehicle, "v", "vehicle", _token("vehicle", 600))
        assert (await recv(relay))["type"] == "peers"
        last = await _until_closed(relay, LIFETIME_S + TIMEOUT_S)
        assert relay.close_code == 1008 and relay.close_reason == "token expired"
        assert last[-1]["type"] == "error" and "token expired" in last[-1]["reason"]
        # The vehicle is told, as of any peer that leaves, and its messages reach no one.
        assert (await recv(vehicle)) == {"type": "leave", "from": "r"}
        assert (await recv(vehicle))["peers"] == []
        await vehicle.send(json.dumps({"type": "offer", "to": "r", "sdp": "v=0"}))
        assert "no peer named 'r'" in (await recv(vehicle))["reason"]


async def test_a_session_that_renews_outlives_several_lifetimes_of_its_tokens(
    guarded: RunningServer,
) -> None:
    async with connect(guarded.ws_url) as relay, connect(guarded.ws_url) as vehicle:
        reply = await _login(relay, "r", "relay", _token("relay", LIFETIME_S))
        # The login reply says when to renew: before the token expires, with room to spare.
        assert 0 < reply["renewIn"] < LIFETIME_S
        await _login(vehicle, "v", "vehicle", _token("vehicle", 600))
        assert (await recv(relay))["type"] == "peers"
        started, renewals = time.monotonic(), 0
        while time.monotonic() - started < 3 * LIFETIME_S:
            await asyncio.sleep(reply["renewIn"])
            await relay.send(json.dumps({"type": "renew"}))
            reply = await recv(relay)
            assert reply["type"] == "renewed", reply
            claims = tokens.verify(SECRET, reply["token"], now=time.time(), room="lab")
            assert claims.role == "relay" and claims.exp > time.time() + LIFETIME_S / 2
            renewals += 1
        assert renewals >= 3
        # Still in the room, still receiving.
        await vehicle.send(json.dumps({"type": "offer", "to": "r", "sdp": "v=0 still"}))
        assert (await recv(relay))["sdp"] == "v=0 still"


async def test_a_renewal_with_a_token_for_another_room_or_role_is_refused(
    guarded: RunningServer,
) -> None:
    async with connect(guarded.ws_url) as relay:
        await _login(relay, "r", "relay", _token("relay", 600))
        for wrong in (_token("relay", 600, room="elsewhere"), _token("client", 600)):
            await relay.send(json.dumps({"type": "renew", "token": wrong}))
            error = await recv(relay)
            assert error["type"] == "error" and error["ref"] == "renew", error
        given = _token("relay", 900)
        await relay.send(json.dumps({"type": "renew", "token": given}))
        assert (await recv(relay))["token"] == given


async def test_a_rosbridge_session_ends_at_its_token_s_expiry_unless_it_authenticates_again(
    guarded: RunningServer,
) -> None:
    # Issue 37.4: a /rosbridge session published after its token's expiry.
    url = rosbridge_url(guarded)
    async with connect(url) as lapsing, connect(url) as renewing:
        for ws in (lapsing, renewing):
            await ws.send(json.dumps({"op": "auth", "token": _token("vehicle", LIFETIME_S)}))
        started = time.monotonic()
        while time.monotonic() - started < 2 * LIFETIME_S:
            await asyncio.sleep(LIFETIME_S / 3)
            await renewing.send(json.dumps({"op": "auth", "token": _token("vehicle", LIFETIME_S)}))
        last = await _until_closed(lapsing, TIMEOUT_S)
        assert lapsing.close_code == 1008 and lapsing.close_reason == "token expired"
        assert last and "token expired" in last[-1]["msg"]
        publish = {"op": "publish", "topic": "/turtle1/cmd_vel", "msg": {"linear": {"x": 1.0}}}
        await renewing.send(json.dumps(publish))
        await renewing.send(json.dumps({"op": "call_service", "id": 1, "service": "/rosapi/nodes"}))
        assert (await recv(renewing))["result"] is True
