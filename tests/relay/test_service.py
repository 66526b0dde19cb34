"""``autopilot relay``: the headless relay page joins its room, comes back when its browser is
killed, and SIGTERM ends it and everything it started."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time

import pytest
from websockets.asyncio.client import connect

from app.relay.service import RelayService
from app.server.serve import RunningServer
from tests.helpers.processes import browser_processes, cmdline, descendants, wait_all_gone
from tests.helpers.waiting import eventually

pytestmark = [pytest.mark.browser, pytest.mark.slow]


async def roster(server: RunningServer, room: str = "default") -> list[dict[str, str]]:
    """Who is in ``room``, as a client that logs in and leaves at once sees it."""
    async with connect(server.ws_url) as ws:
        name = f"probe-{time.monotonic_ns()}"
        await ws.send(json.dumps({"type": "login", "name": name, "role": "client", "room": room}))
        reply = json.loads(await ws.recv())
        await ws.send(json.dumps({"type": "leave"}))
    assert reply["success"], reply
    peers: list[dict[str, str]] = reply["peers"]
    return peers


async def wait_for_relay_in(server: RunningServer, room: str, what: str) -> None:
    """Poll the roster until the relay page has joined ``room`` (it joins after it loads)."""
    relay = {"name": "relay", "role": "relay"}
    try:
        async with asyncio.timeout(30):
            while relay not in await roster(server, room):
                await asyncio.sleep(0.2)
    except TimeoutError:
        raise AssertionError(f"timed out after 30 s waiting for {what}") from None


async def test_relay_page_comes_back_after_its_browser_is_killed(server: RunningServer) -> None:
    before = browser_processes()
    service = RelayService(server.url, room="r1")
    stop = asyncio.Event()
    task = asyncio.create_task(service.run(stop))
    try:
        await eventually(lambda: service.starts == 1, 60, "the relay page")
        await wait_for_relay_in(server, "r1", "the relay page to join its room")
        ours = browser_processes() - before
        assert len(ours) == 1
        os.kill(ours.pop(), signal.SIGKILL)
        await eventually(lambda: service.starts == 2, 60, "the relay page to come back")
        await wait_for_relay_in(server, "r1", "the restarted relay page to rejoin its room")
    finally:
        stop.set()
        await asyncio.wait_for(task, 30)
    assert wait_all_gone(browser_processes() - before) == []


def test_sigterm_ends_the_relay_and_its_browser(server: RunningServer) -> None:
    with subprocess.Popen(
        [sys.executable, "-m", "app.cli", "relay", "--server", server.url, "--room", "r2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as process:
        assert process.stdout is not None
        for line in process.stdout:
            if "relay page running" in line:
                break
        children = descendants(process.pid)
        assert any("chromium" in cmdline(pid) for pid in children)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 0
        assert wait_all_gone(children) == []
