"""``autopilot demo`` prints a Foxglove address, and the official client reads it: every channel
of the whole system (server, headless relay, agent) valid, once a client starts piloting. The
demo's robot that carries its camera (so the camera's calibration, and Twists that turn toward
the target's side), piloted by the onboard law."""

from __future__ import annotations

import asyncio
import json
import re
import socket
from typing import Any

import pytest
from websockets.asyncio.client import connect

from app.protocol.video import VIDEO_SIZE
from tests.helpers.demo import running_demo, wait_for_line
from tests.helpers.waiting import wait_until
from tests.vehicle_agent.test_foxglove import EVERY_TOPIC, MODE, check_view, view

pytestmark = [pytest.mark.browser, pytest.mark.e2e, pytest.mark.slow]
# Nobody changes the mode here.
TOPICS = [topic for topic in EVERY_TOPIC if topic != MODE]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


def _accepts(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


async def _pilot_and_view(ws_url: str, token: str, foxglove_url: str) -> dict[str, Any]:
    """Log in as a client, start piloting (again each second until the relay has its video),
    and read the Foxglove server meanwhile."""
    async with connect(ws_url) as client:
        login = {"type": "login", "name": "fox", "role": "client", "room": "default"}
        await client.send(json.dumps({**login, "token": token}))
        assert json.loads(await client.recv())["success"]

        async def start() -> None:
            while True:
                await client.send(json.dumps({"type": "start"}))
                await asyncio.sleep(1.0)

        starting = asyncio.create_task(start())
        try:
            return await view(foxglove_url, timeout_s=60, topics=TOPICS)
        finally:
            starting.cancel()


def test_the_demo_serves_foxglove_at_the_address_it_prints() -> None:
    port = _free_port()
    demo = ["--robot", "diffdrive", "--profile", "onboard", "--foxglove-port", str(port)]
    with running_demo(demo) as (_, lines):
        url = wait_for_line(lines, r"(http://\S+/client\?room=default#token=\S+)", 60).group(1)
        address = wait_for_line(lines, r"Foxglove .*(ws://\S+)", 10).group(1)
        assert address == f"ws://127.0.0.1:{port}"
        base, token = url.split("/client")[0], url.split("#token=", 1)[1]
        ws_url = re.sub(r"^http", "ws", base) + "/ws"
        # The demo prints its addresses as it starts the agent, which serves a moment later.
        wait_until(lambda: _accepts(port), 60, "the agent's Foxglove server", poll_s=0.2)
        result = asyncio.run(_pilot_and_view(ws_url, token, address))
    check_view(result, TOPICS, VIDEO_SIZE)
