"""The Foxglove view on the network, behind a token (``vehicle_agent/foxglove_gate.py``): the
official client (``@foxglove/ws-protocol``) reads every channel over ``wss://`` with a token in
the URL, as Foxglove passes it; viewers without a valid token of the vehicle's room are closed
with 1008 and the reason, a plain ``ws://`` one gets no WebSocket at all, a token's expiry ends
its viewer, and none of it stops the vehicle. ``autopilot vehicle --foxglove HOST:PORT`` with a
secret puts the gate in front, and refuses to start without TLS.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import ssl
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidMessage, InvalidStatus

from app.protocol import tokens
from app.protocol.close_codes import CloseCode
from app.server import tls
from app.server.serve import RunningServer
from app.tools.bench.foxglove import PilotedAgent
from app.tools.bench.foxglove_viewer import SUBPROTOCOLS
from tests.helpers.waiting import eventually
from tests.vehicle_agent.test_foxglove import ROBOT, check_view, view
from vehicle_agent import cli as agent_cli
from vehicle_agent import foxglove
from vehicle_agent.foxglove_gate import TOKEN_HINT, FoxgloveGate, server_tls

SECRET = "foxglove-gate-test-secret"
ROOM = "lab"


def token(role: tokens.TokenRole = "client", room: str = ROOM, ttl_s: float = 60) -> str:
    """A token of ``role`` in ``room``, signed with the vehicle's secret."""
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=ttl_s)


@pytest.fixture
def tls_files(tmp_path: Path) -> tls.TlsFiles:
    """A certificate for this machine's names and addresses, from a CA made for the test."""
    return tls.self_signed(tmp_path)


def trusting(files: tls.TlsFiles) -> ssl.SSLContext:
    """A client context that trusts the test's CA (and checks the name)."""
    return ssl.create_default_context(cafile=str(files.ca_file))


@contextlib.asynccontextmanager
async def gated_agent(
    server: RunningServer, files: tls.TlsFiles
) -> AsyncIterator[tuple[PilotedAgent, FoxgloveGate]]:
    """A piloted agent whose Foxglove view is served through a gate on a loopback port."""
    piloted = PilotedAgent(server.url, toggle_mode=True)
    async with piloted.running() as live:
        context = server_tls(files.certfile, files.keyfile)
        gate = FoxgloveGate("127.0.0.1", 0, live.url, context, SECRET, ROOM)
        live.put_behind(gate, "127.0.0.1")
        yield piloted, gate


async def first_op(ws: ClientConnection) -> str:
    """The op of the first message the Foxglove server sends (its ``serverInfo``)."""
    message = json.loads(await asyncio.wait_for(ws.recv(), 5))
    return str(message["op"])


async def refusal(url: str, files: tls.TlsFiles, **options: object) -> tuple[int, str]:
    """The close code and reason a viewer at ``url`` gets, having been given no message."""
    async with connect(url, ssl=trusting(files), subprotocols=SUBPROTOCOLS, **options) as ws:
        with pytest.raises(ConnectionClosed) as closed:
            await asyncio.wait_for(ws.recv(), 5)
    received = closed.value.rcvd
    assert received is not None
    return received.code, received.reason


async def test_the_official_client_reads_every_channel_over_wss_with_a_token(
    server: RunningServer, tls_files: tls.TlsFiles
) -> None:
    async with gated_agent(server, tls_files) as (piloted, gate):
        live = piloted.live
        assert live.url == f"wss://127.0.0.1:{gate.port}/"
        result = await view(f"{live.url}?token={token()}", ca=tls_files.ca_file)
        check_view(result)
        assert result["capabilities"] == []
        # Without a token, the official client is told why.
        refused = await view(live.url, timeout_s=5, ca=tls_files.ca_file)
    assert refused["error"] == f"closed by the server: 1008 {TOKEN_HINT}"
    assert gate.admitted == 1 and gate.refused == 1


async def test_viewers_without_a_valid_token_are_refused_and_the_vehicle_drives_on(
    server: RunningServer, tls_files: tls.TlsFiles
) -> None:
    async with gated_agent(server, tls_files) as (piloted, gate):
        url = piloted.live.url
        await eventually(lambda: bool(piloted.twists), 10, "a Twist")
        before = len(piloted.goals)
        fleet = tokens.sign(SECRET, tokens.ALL_ROOMS, "fleet", now=time.time())
        other = tokens.sign("another-secret-of-16-chars", ROOM, "client", now=time.time())
        refused = {
            "no token": await refusal(url, tls_files),
            "bad signature": await refusal(f"{url}?token={other}", tls_files),
            "wrong room": await refusal(f"{url}?token={token(room='other')}", tls_files),
            "fleet": await refusal(f"{url}?token={fleet}", tls_files),
        }
        assert refused["no token"] == (CloseCode.POLICY_VIOLATION, TOKEN_HINT)
        assert refused["bad signature"][1].startswith("token refused: bad signature")
        assert refused["wrong room"][1].startswith("token refused: wrong room")
        # A fleet token is for every room's row on the fleet page, and nothing else.
        assert refused["fleet"][1].startswith("token refused: wrong room")
        assert all(code == CloseCode.POLICY_VIOLATION for code, _ in refused.values())
        # An expired token: signed to have ended a minute ago.
        old = tokens.sign(SECRET, ROOM, "client", now=time.time() - 120, ttl_s=60)
        code, reason = await refusal(f"{url}?token={old}", tls_files)
        assert (code, reason.split(" (")[0]) == (1008, "token refused: expired")
        # Plain ws:// on the TLS port: no WebSocket, no message.
        plain = url.replace("wss://", "ws://", 1)
        with pytest.raises(InvalidMessage, match="did not receive a valid HTTP response"):
            async with connect(plain, subprotocols=SUBPROTOCOLS, open_timeout=3):
                pass
        # A token in an Authorization header is taken too, and the SDK's subprotocol chosen.
        bearer = {"Authorization": f"Bearer {token('relay')}"}
        async with connect(
            url, ssl=trusting(tls_files), subprotocols=SUBPROTOCOLS, additional_headers=bearer
        ) as ws:
            assert ws.subprotocol == "foxglove.sdk.v1"
            assert await first_op(ws) == "serverInfo"
        # The vehicle handles every goal sent from the first refusal on.
        await eventually(lambda: len(piloted.goals) >= before + 5, 5, "five more goals")
        sent = set(piloted.goals[before:])
        await eventually(lambda: sent <= piloted.handled, 5, "every goal handled")
    assert gate.refused == 5 and gate.admitted == 1


async def test_a_viewer_is_closed_when_its_token_expires(
    server: RunningServer, tls_files: tls.TlsFiles
) -> None:
    async with gated_agent(server, tls_files) as (piloted, _):
        short = token(ttl_s=2)
        expires = tokens.verify(SECRET, short, now=time.time()).exp
        url = f"{piloted.live.url}?token={short}"
        async with connect(url, ssl=trusting(tls_files), subprotocols=SUBPROTOCOLS) as ws:
            assert await first_op(ws) == "serverInfo"
            with pytest.raises(ConnectionClosed) as closed:
                while True:
                    await asyncio.wait_for(ws.recv(), 5)
        assert time.time() >= expires
    received = closed.value.rcvd
    assert received is not None
    assert (received.code, received.reason) == (CloseCode.POLICY_VIOLATION, "token expired")


def test_with_a_secret_the_vehicle_serves_the_network_only_over_tls_behind_a_token(
    tls_files: tls.TlsFiles,
) -> None:
    parser = argparse.ArgumentParser()
    agent_cli.add_arguments(parser)
    plain = parser.parse_args(["--foxglove", "0.0.0.0:0"])
    with pytest.raises(OSError, match="--foxglove-certfile"):
        foxglove.start(plain, ROBOT, SECRET, ROOM)
    files = ["--foxglove-certfile", str(tls_files.certfile)]
    files += ["--foxglove-keyfile", str(tls_files.keyfile)]
    args = parser.parse_args(["--foxglove", "0.0.0.0:0", *files])
    live = foxglove.start(args, ROBOT, SECRET, ROOM)
    assert live is not None and live.gate is not None
    try:
        # The SDK's server is on this machine only; the gate faces the network, over TLS.
        assert live.server_url.startswith("ws://127.0.0.1:")
        assert live.url == f"wss://0.0.0.0:{live.gate.port}/"
        url = f"wss://127.0.0.1:{live.gate.port}/?token={token()}"

        async def admitted() -> str:
            async with connect(url, ssl=trusting(tls_files), subprotocols=SUBPROTOCOLS) as ws:
                return await first_op(ws)

        assert asyncio.run(admitted()) == "serverInfo"
    finally:
        live.close()
    # Without a secret there is no token to ask for: served as asked, with a warning.
    open_args = parser.parse_args(["--foxglove", "0.0.0.0:0"])
    unguarded = foxglove.start(open_args, ROBOT, None, ROOM)
    assert unguarded is not None and unguarded.gate is None
    unguarded.close()
    half = parser.parse_args(["--foxglove", "0", "--foxglove-certfile", str(tls_files.certfile)])
    with pytest.raises(OSError, match="go together"):
        foxglove.start(half, ROBOT, None, ROOM)


async def test_a_viewer_offering_only_an_unknown_subprotocol_gets_the_sdks_refusal(
    server: RunningServer, tls_files: tls.TlsFiles
) -> None:
    async with gated_agent(server, tls_files) as (piloted, _):
        url = f"{piloted.live.url}?token={token()}"
        with pytest.raises(InvalidStatus) as refused:
            async with connect(url, ssl=trusting(tls_files), subprotocols=["x.v1"]):  # type: ignore[list-item]
                pass
    assert refused.value.response.status_code == 400
