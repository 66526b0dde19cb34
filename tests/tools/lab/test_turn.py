"""Credentials minted by the server's function are the ones a real coturn accepts.

Run inside the private namespace: ``scripts/in-netns python3 -m pytest tests/tools/lab -q``.
"""

from __future__ import annotations

import asyncio
import time

import pytest
from aioice import stun
from aioice.turn import TurnClientUdpProtocol

from app.server.turn import mint_turn_credentials
from app.tools.lab import Lab
from app.tools.lab.coturn import TURN_PORT
from app.tools.lab.lab import CLOUD

SERVER = (CLOUD, TURN_PORT)


async def _allocate(lab: Lab, username: str, password: str) -> tuple[str, int]:
    """A TURN Allocate from the robot site (behind its NAT) with aioice's TURN client."""
    sock = lab.socket("robot")
    sock.connect(SERVER)
    transport, protocol = await asyncio.get_running_loop().create_datagram_endpoint(
        lambda: TurnClientUdpProtocol(
            SERVER, username=username, password=password, lifetime=60, channel_refresh_time=50
        ),
        sock=sock,
    )
    try:
        relayed: tuple[str, int] = await protocol.connect()
        await protocol.delete()
        return relayed
    finally:
        transport.close()


async def test_coturn_accepts_minted_credentials_and_relays_from_the_cloud(lab: Lab) -> None:
    username, password = mint_turn_credentials(lab.turn_secret, "robot", 600, time.time())
    relayed = await _allocate(lab, username, password)
    assert relayed[0] == CLOUD


@pytest.mark.parametrize(
    "spoil",
    [
        pytest.param(lambda u, p, s: (u, p[::-1]), id="wrong-password"),
        pytest.param(
            lambda u, p, s: mint_turn_credentials(s + "x", "robot", 600, time.time()),
            id="other-secret",
        ),
        pytest.param(
            lambda u, p, s: mint_turn_credentials(s, "robot", 60, time.time() - 3600),
            id="expired",
        ),
    ],
)
async def test_coturn_refuses_spoiled_credentials(lab: Lab, spoil: object) -> None:
    username, password = mint_turn_credentials(lab.turn_secret, "robot", 600, time.time())
    bad_username, bad_password = spoil(username, password, lab.turn_secret)  # type: ignore[operator]
    with pytest.raises(stun.TransactionFailed) as refused:
        await _allocate(lab, bad_username, bad_password)
    assert refused.value.response.error_code == 401
