"""``autopilot relay --metrics-port`` and ``autopilot vehicle --metrics-port``, piloted for real:
the relay page in headless Chromium analyses the agent's synthetic video, and both processes'
``/metrics`` show the goals, the snapshot timings and the link."""

from __future__ import annotations

import asyncio
import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator

import pytest
from websockets.asyncio.client import connect

from app.server.serve import RunningServer
from app.supervise import free_port, stop_process
from tests.helpers.metrics import Samples, scrape

pytestmark = [pytest.mark.browser, pytest.mark.slow]

ROOM = "metrics"


@pytest.fixture
def piloted(server: RunningServer) -> Iterator[tuple[str, str]]:
    """A relay and a vehicle agent in ``ROOM``, each serving metrics: their metrics URLs."""
    relay_port, vehicle_port = free_port(), free_port()
    common = ["--server", server.url, "--room", ROOM]
    env = {k: v for k, v in os.environ.items() if not k.startswith("AUTOPILOT_")}
    processes = [
        subprocess.Popen(
            [sys.executable, "-m", "app.cli", command, *common, "--metrics-port", str(port)],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        for command, port in (("relay", relay_port), ("vehicle", vehicle_port))
    ]
    try:
        yield (
            f"http://127.0.0.1:{relay_port}/metrics",
            f"http://127.0.0.1:{vehicle_port}/metrics",
        )
    finally:
        for process in processes:
            stop_process(process, 15)


async def test_piloting_shows_in_the_relays_and_the_vehicles_metrics(
    server: RunningServer, piloted: tuple[str, str]
) -> None:
    relay_url, vehicle_url = piloted
    deadline = time.monotonic() + 60
    relay: Samples = {}
    async with connect(server.ws_url) as client:
        await client.send(
            json.dumps({"type": "login", "name": "c", "role": "client", "room": ROOM})
        )
        assert json.loads(await client.recv())["success"]
        # Start Piloting, again until the relay has its vehicle's video and pilots.
        while time.monotonic() < deadline:
            await client.send(json.dumps({"type": "start"}))
            await asyncio.sleep(1.0)
            relay = scrape(relay_url)
            if relay.get(("autopilot_relay_goals_sent_total", ()), 0) >= 5:
                break
        else:
            pytest.fail(f"no goals in the relay's metrics within 60 s: {relay}")
        await asyncio.sleep(1.5)  # one more poll of the page, and of the agent's counters
        relay, vehicle = scrape(relay_url), scrape(vehicle_url)
    assert relay[("autopilot_relay_pages", ())] == 1
    assert relay[("autopilot_relay_piloting", ())] == 1
    assert relay[("autopilot_relay_goals_per_second", ())] > 0
    snapshots = relay[("autopilot_relay_snapshots_total", ())]
    # Each snapshot's delay is observed once: as many observations as snapshots counted.
    assert relay[("autopilot_relay_processing_seconds_count", ())] == snapshots > 0
    assert 0 < relay[("autopilot_relay_processing_seconds_sum", ())] / snapshots < 1.0
    assert vehicle[("autopilot_vehicle_link_up", ())] == 1
    assert vehicle[("autopilot_vehicle_mode", ())] == 0
    # (Not compared with the relay's count: the relay's is up to a poll behind.)
    assert vehicle[("autopilot_vehicle_goals_applied_total", ())] > 0
    assert vehicle[("autopilot_vehicle_twists_total", ())] > 0
    assert vehicle[("autopilot_vehicle_goal_age_seconds_count", ())] > 0
