"""Debian's Prometheus scrapes a running server's ``/metrics`` and loads the alert rules; the
rules pass ``promtool``; the Grafana dashboard and docs/operations.md name every metric there is.

Loopback only: Prometheus listens on 127.0.0.1 and scrapes nothing but the server under test.
"""

from __future__ import annotations

import contextlib
import json
import re
import shutil
import subprocess
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from app.metrics import MetricsServer, start_metrics_server
from app.relay.metrics import RelayMetrics
from app.resources import APP_DIR
from app.server.metrics import ServerMetrics
from app.server.serve import RunningServer
from app.supervise import free_port, stop_process
from tests.helpers.waiting import wait_until
from vehicle_agent.metrics import VehicleMetrics

DOCS = APP_DIR.parent / "docs"
ALERTS = DOCS / "alerts.yml"
ALERTS_TEST = APP_DIR.parent / "tests" / "data" / "alerts_test.yml"
PROMETHEUS = shutil.which("prometheus") or "/usr/bin/prometheus"
PROMTOOL = shutil.which("promtool") or "/usr/bin/promtool"

needs_prometheus = pytest.mark.skipif(
    not Path(PROMETHEUS).exists(), reason="Debian's prometheus is not installed (scripts/setup)"
)
needs_promtool = pytest.mark.skipif(
    not Path(PROMTOOL).exists(), reason="promtool is not installed (Debian's prometheus)"
)


def metric_names() -> set[str]:
    """Every metric the server, the agent and the relay export, as queries name them."""
    return {
        family.name + "_total" if family.type == "counter" else family.name
        for metrics in (ServerMetrics(), VehicleMetrics(), RelayMetrics())
        for family in metrics.registry.collect()
    }


@pytest.fixture
def metrics_listener(server: RunningServer) -> Iterator[MetricsServer]:
    """The running server's metrics on a listener of their own, as ``--metrics-port`` opens."""
    listener = start_metrics_server(server.metrics.registry, 0)
    yield listener
    listener.close()


@contextlib.contextmanager
def running_prometheus(tmp_path: Path, target_port: int) -> Iterator[str]:
    """Debian's Prometheus on loopback scraping ``127.0.0.1:target_port`` every second, with the
    alert rules loaded; its base URL. Stopped on exit (its storage is in ``tmp_path``)."""
    config = tmp_path / "prometheus.yml"
    config.write_text(
        json.dumps(  # JSON is YAML
            {
                "global": {"scrape_interval": "1s", "evaluation_interval": "1s"},
                "rule_files": [str(ALERTS)],
                "scrape_configs": [
                    {
                        "job_name": "autopilot",
                        "static_configs": [{"targets": [f"127.0.0.1:{target_port}"]}],
                    }
                ],
            }
        )
    )
    port = free_port()
    log = (tmp_path / "prometheus.log").open("wb")
    process = subprocess.Popen(
        [
            PROMETHEUS,
            f"--config.file={config}",
            f"--storage.tsdb.path={tmp_path / 'prometheus-data'}",
            f"--web.listen-address=127.0.0.1:{port}",
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
    )
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        stop_process(process, 10)
        log.close()


def wait_for_scrape(prometheus: str) -> None:
    """Until Prometheus has scraped its one target and found it up."""

    def up() -> bool:
        try:
            result = api(prometheus, "query", query="up")["result"]
        except OSError:
            return False  # not listening yet
        return [r["value"][1] for r in result] == ["1"]

    wait_until(up, 30, "Prometheus to scrape its target with up = 1", poll_s=0.25)


@pytest.fixture
def prometheus(tmp_path: Path, metrics_listener: MetricsServer) -> Iterator[str]:
    """Prometheus scraping ``metrics_listener``."""
    with running_prometheus(tmp_path, metrics_listener.port) as url:
        yield url


def api(base: str, path: str, **query: str) -> Any:
    """The ``data`` of a Prometheus HTTP API answer."""
    url = f"{base}/api/v1/{path}" + (f"?{urllib.parse.urlencode(query)}" if query else "")
    with urllib.request.urlopen(url, timeout=5) as response:
        answer = json.loads(response.read())
    assert answer["status"] == "success", answer
    return answer["data"]


@needs_prometheus
def test_prometheus_scrapes_the_server(prometheus: str) -> None:
    wait_for_scrape(prometheus)
    peers = api(prometheus, "query", query="autopilot_peers")["result"]
    assert {p["metric"]["role"] for p in peers} == {"vehicle", "relay", "client"}
    assert all(p["metric"]["job"] == "autopilot" for p in peers)
    groups = api(prometheus, "rules")["groups"]
    alerts = {rule["name"] for group in groups for rule in group["rules"]}
    assert alerts == {"AutopilotNoGoalsWhilePiloting", "AutopilotRefusalsSpiking"}


@needs_promtool
def test_alert_rules_pass_promtool() -> None:
    check = subprocess.run(
        [PROMTOOL, "check", "rules", str(ALERTS)], capture_output=True, text=True, timeout=60
    )
    assert check.returncode == 0, check.stdout + check.stderr
    assert "SUCCESS: 2 rules found" in check.stdout
    # The rules' own unit tests: each alert fires when it should and only then.
    test = subprocess.run(
        [PROMTOOL, "test", "rules", ALERTS_TEST.name],
        cwd=ALERTS_TEST.parent,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert test.returncode == 0, test.stdout + test.stderr


def test_dashboard_panels_use_metrics_that_exist() -> None:
    dashboard = json.loads((DOCS / "grafana-dashboard.json").read_text())
    exprs = " ".join(t["expr"] for panel in dashboard["panels"] for t in panel["targets"])
    exported = metric_names()
    # A histogram is queried by its series: name_bucket, name_sum, name_count.
    used = {
        name if name in exported else re.sub(r"_(bucket|sum|count)$", "", name)
        for name in re.findall(r"\bautopilot_[a-z_]+", exprs)
    }
    assert used <= exported, f"not exported: {used - exported}"
    assert used == exported, f"no panel for {exported - used}"


def test_operations_doc_lists_every_metric() -> None:
    listed = set(re.findall(r"`(autopilot_[a-z_]+)", (DOCS / "operations.md").read_text()))
    assert metric_names() <= listed, f"not in docs/operations.md: {metric_names() - listed}"
