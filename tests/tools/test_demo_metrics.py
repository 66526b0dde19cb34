"""``autopilot demo --metrics-port``: the demo's server serves ``/metrics``, which parses, counts
the demo's own relay and vehicle, and Debian's Prometheus scrapes (``up`` = 1,
``autopilot_peers`` present). Everything on loopback."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from app.supervise import free_port
from tests.helpers.metrics import peers
from tests.helpers.processes import descendants, kill_tree, wait_all_gone
from tests.helpers.waiting import wait_until
from tests.server.test_prometheus import PROMETHEUS, api, running_prometheus, wait_for_scrape

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.mark.skipif(not Path(PROMETHEUS).exists(), reason="Debian's prometheus is not installed")
def test_demo_metrics_count_its_children_and_prometheus_scrapes_them(tmp_path: Path) -> None:
    port, metrics_port = free_port(), free_port()
    url = f"http://127.0.0.1:{metrics_port}/metrics"
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "demo", "--port", str(port)]
        + ["--metrics-port", str(metrics_port), "--state-dir", str(tmp_path)],
        env={k: v for k, v in os.environ.items() if not k.startswith("AUTOPILOT_")},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        wait_until(
            lambda: peers(url) == {"vehicle": 1, "relay": 1, "client": 0},
            60,
            "the demo's relay and vehicle in its server's metrics",
            poll_s=0.25,
        )
        with running_prometheus(tmp_path, metrics_port) as prometheus:
            wait_for_scrape(prometheus)
            result = api(prometheus, "query", query="autopilot_peers")["result"]
            assert {r["metric"]["role"]: r["value"][1] for r in result} == {
                "vehicle": "1",
                "relay": "1",
                "client": "0",
            }
        children = descendants(process.pid)
        process.send_signal(signal.SIGTERM)
        assert process.wait(timeout=60) == 0
        assert wait_all_gone(children) == []
    finally:
        kill_tree(process)
