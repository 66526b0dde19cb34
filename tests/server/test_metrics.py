"""The server's Prometheus metrics: ``autopilot serve --metrics-port`` serves text that parses,
and the counters move with real signaling and rosbridge traffic over real sockets."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator

import pytest
import websockets
from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.parser import text_string_to_metric_families
from websockets.asyncio.client import ClientConnection, connect

from app.metrics import start_metrics_server
from app.protocol import tokens
from app.protocol.rooms import Role
from app.server.config import Settings
from app.server.metrics import MESSAGE_TYPES, ServerMetrics
from app.server.serve import RunningServer
from app.server.websocket import Outboxes, SocketPolicy
from app.signaling.hub import REFUSALS
from app.supervise import free_port, stop_process
from tests.helpers.metrics import scrape
from tests.helpers.sockets import login, recv, rosbridge_url
from tests.helpers.waiting import eventually, wait_until

SECRET = "metrics-test-secret-0123456789"


def value(registry: CollectorRegistry, name: str, **labels: str) -> float:
    """A sample's value; 0 for a series that does not exist yet."""
    return registry.get_sample_value(name, labels) or 0.0


@pytest.fixture
def serve_process() -> Iterator[Callable[..., tuple[str, str]]]:
    """Start ``autopilot serve`` with ``--metrics-port``: (base URL, metrics URL)."""
    processes: list[subprocess.Popen[bytes]] = []

    def start(*extra: str) -> tuple[str, str]:
        port, metrics_port = free_port(), free_port()
        process = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "serve", "--port", str(port)]
            + ["--metrics-port", str(metrics_port), *extra],
            env={k: v for k, v in os.environ.items() if not k.startswith("AUTOPILOT_")},
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        processes.append(process)
        base, metrics = f"http://127.0.0.1:{port}", f"http://127.0.0.1:{metrics_port}/metrics"

        def up() -> bool:
            try:
                scrape(metrics)
                urllib.request.urlopen(f"{base}/healthz", timeout=1).close()
            except OSError:
                return False
            return True

        wait_until(up, 20, "autopilot serve and its metrics listener", poll_s=0.1)
        return base, metrics

    yield start
    for process in processes:
        stop_process(process, 5)


async def test_serve_metrics_parse_and_count_real_traffic(
    serve_process: Callable[..., tuple[str, str]],
) -> None:
    base, metrics = serve_process()
    before = scrape(metrics)
    # Every series is there from the start, at 0: dashboards show 0, not "no data".
    for reason in REFUSALS:
        assert before[("autopilot_refusals_total", (("reason", reason),))] == 0
    for kind in MESSAGE_TYPES:
        assert before[("autopilot_signaling_messages_total", (("type", kind),))] == 0
    ws_url = base.replace("http", "ws", 1) + "/ws"
    async with connect(ws_url) as client, connect(ws_url) as relay:
        await login(client, "c", "client")
        await login(relay, "r", "relay")
        assert (await recv(client))["type"] == "peers"  # the relay joined
        await client.send(json.dumps({"type": "hello"}))  # no such message type
        assert (await recv(client))["type"] == "error"
        await client.send(json.dumps({"type": "answer", "to": "r", "sdp": "x"}))  # relay's only
        assert (await recv(client))["type"] == "error"
        # A page of another site may not open the socket at all.
        with pytest.raises(websockets.InvalidStatus):
            async with connect(ws_url, origin=websockets.Origin("https://evil.example")):
                pass

        def counted() -> bool:
            after = scrape(metrics)
            return after[("autopilot_peers", (("role", "client"),))] == 1

        # The gauges are sampled once a second.
        await asyncio.to_thread(wait_until, counted, 5, "the peers gauge", poll_s=0.2)
        after = scrape(metrics)
    assert after[("autopilot_signaling_messages_total", (("type", "login"),))] == 2
    assert after[("autopilot_signaling_messages_total", (("type", "answer"),))] == 1
    assert after[("autopilot_signaling_messages_total", (("type", "other"),))] == 1
    assert after[("autopilot_refusals_total", (("reason", "invalid"),))] == 2
    assert after[("autopilot_refusals_total", (("reason", "origin"),))] == 1
    assert after[("autopilot_rooms", ())] == 1
    assert after[("autopilot_peers", (("role", "relay"),))] == 1
    assert after[("autopilot_peers", (("role", "vehicle"),))] == 0
    # turtlesim's 16 ms tick: 62.5 steps a second, less whatever a busy machine loses.
    assert 30 < after[("autopilot_simulator_tick_rate_hz", ())] < 70


def test_a_taken_metrics_port_is_one_line_and_exit_1() -> None:
    metrics = start_metrics_server(CollectorRegistry(), 0)
    try:
        result = subprocess.run(
            [sys.executable, "-m", "app.cli", "serve", "--port", str(free_port())]
            + ["--metrics-port", str(metrics.port)],
            env={k: v for k, v in os.environ.items() if not k.startswith("AUTOPILOT_")},
            capture_output=True,
            text=True,
            timeout=60,
        )
    finally:
        metrics.close()
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    assert f"cannot serve metrics on 127.0.0.1:{metrics.port}" in result.stderr


async def _login(ws: ClientConnection, name: str, role: Role, token: str | None) -> bool:
    login = {"type": "login", "name": name, "role": role}
    await ws.send(json.dumps(login | ({"token": token} if token else {})))
    success: bool = (await recv(ws))["success"]
    if not success:
        assert (await recv(ws))["type"] == "error"  # every refusal's error follows the reply
    return success


async def _drain(ws: ClientConnection) -> None:
    with contextlib.suppress(websockets.ConnectionClosed):
        while True:
            await ws.recv()


async def test_refusals_by_reason(start_server: Callable[[Settings], RunningServer]) -> None:
    server = start_server(
        Settings(environment="development", token=None, secret=SECRET, max_connections=2)
    )
    registry = server.metrics.registry

    def token(role: Role) -> str:
        return tokens.sign(SECRET, "default", role, now=time.time())

    async with connect(server.ws_url) as client, connect(server.ws_url) as relay:
        assert not await _login(client, "c", "client", None)  # no token: auth
        assert await _login(client, "c", "client", token("client"))
        assert await _login(relay, "r", "relay", token("relay"))
        # A third socket is over max_connections=2: caps.
        async with connect(server.ws_url) as third:
            with pytest.raises(websockets.ConnectionClosed):
                await asyncio.wait_for(third.recv(), 5)
        # A flood beyond the sender's token bucket (a burst of 100): rate_limit. Both sockets
        # read what they get meanwhile, or their close handshakes would wait behind it.
        drains = [asyncio.create_task(_drain(ws)) for ws in (client, relay)]
        for _ in range(120):
            await client.send(json.dumps({"type": "stop"}))
        await eventually(
            lambda: value(registry, "autopilot_refusals_total", reason="rate_limit") > 0,
            what="a rate-limit refusal",
        )
        # The flood may or may not have got the client closed as abusive (on a slow machine the
        # bucket refills between sends and the refusals are not all in a row): close both.
        await relay.close()
        await client.close()
        await asyncio.wait_for(asyncio.gather(*drains), 30)
    # On /rosbridge a client token may read, not drive: auth once more.
    async with connect(rosbridge_url(server)) as ros:
        await ros.send(json.dumps({"op": "auth", "token": token("client")}))
        await ros.send(json.dumps({"op": "publish", "topic": "/turtle1/cmd_vel", "msg": {}}))
        assert (await recv(ros))["level"] == "error"
    assert value(registry, "autopilot_refusals_total", reason="auth") == 2
    assert value(registry, "autopilot_refusals_total", reason="caps") == 1
    assert value(registry, "autopilot_refusals_total", reason="origin") == 0


async def test_rosbridge_sessions_are_sampled(server: RunningServer) -> None:
    registry = server.metrics.registry
    async with connect(rosbridge_url(server)), connect(rosbridge_url(server)):
        await eventually(
            lambda: value(registry, "autopilot_rosbridge_sessions") == 2,
            timeout=5,
            what="two rosbridge sessions in the gauge",
        )
    await eventually(
        lambda: value(registry, "autopilot_rosbridge_sessions") == 0,
        timeout=5,
        what="the sessions gone from the gauge",
    )


async def test_a_slow_reader_is_counted() -> None:
    metrics = ServerMetrics()
    outboxes: Outboxes[str] = Outboxes(SocketPolicy(1024, 2, 1024), 4)
    outboxes.refused = metrics.refused
    outbox = outboxes.open("peer", "127.0.0.1")
    for n in range(3):  # the third does not fit: the peer is closed as a slow reader
        outbox.send({"n": n})
    assert outbox.shut is not None
    assert value(metrics.registry, "autopilot_refusals_total", reason="slow_reader") == 1


def test_unknown_message_types_share_one_series() -> None:
    metrics = ServerMetrics()
    for kind in ("login", "x" * 40, "DROP TABLE", "other"):
        metrics.message(kind)
    families = list(text_string_to_metric_families(_exposition(metrics.registry)))
    (messages,) = [f for f in families if f.name == "autopilot_signaling_messages"]
    kinds = {s.labels["type"] for s in messages.samples if s.name.endswith("_total")}
    assert kinds == set(MESSAGE_TYPES)
    assert value(metrics.registry, "autopilot_signaling_messages_total", type="other") == 3


def _exposition(registry: CollectorRegistry) -> str:
    return generate_latest(registry).decode()
