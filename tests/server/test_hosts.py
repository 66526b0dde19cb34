"""Without a secret the server answers only the Host names it was started for (DNS rebinding):
HTTP and WebSocket alike, with one log line saying how to allow a name."""

from __future__ import annotations

import argparse
import base64
import logging
import os
import socket
from collections.abc import Callable, Iterator

import pytest

from app.server.config import Settings
from app.server.hosts import allowed_hosts, host_name
from app.server.serve import RunningServer, settings_from, start_in_thread
from tests.helpers.sockets import TIMEOUT_S

SECRET = "hosts-test-secret-0123456789"


def status(server: RunningServer, host: str, path: str = "/healthz", upgrade: bool = False) -> int:
    """The status of a GET of ``path`` (a WebSocket handshake when ``upgrade``) naming
    ``host``, as a page that a rebound name points here would send it."""
    address, port = server.url.split("://", 1)[1].rsplit(":", 1)
    lines = [f"GET {path} HTTP/1.1", f"Host: {host}", "Connection: close"]
    if upgrade:
        key = base64.b64encode(os.urandom(16)).decode()
        lines[2:] = [
            "Connection: Upgrade",
            "Upgrade: websocket",
            "Sec-WebSocket-Version: 13",
            f"Sec-WebSocket-Key: {key}",
            f"Origin: http://{host}",
        ]
    with socket.create_connection((address, int(port)), timeout=TIMEOUT_S) as sock:
        sock.sendall(("\r\n".join(lines) + "\r\n\r\n").encode())
        return int(sock.recv(1024).split(b" ", 2)[1])


@pytest.fixture
def open_server(start_server: Callable[[Settings], RunningServer]) -> RunningServer:
    return start_server(Settings(allowed_hosts=["robot.lan"]))


def test_host_names_are_compared_without_port_brackets_or_case() -> None:
    assert host_name("LocalHost:8000") == "localhost"
    assert host_name("[::1]:8000") == "::1"
    assert host_name("evil.example") == "evil.example"
    assert host_name("") == ""
    allowed = allowed_hosts("10.203.0.1", ["Robot.LAN"])
    assert {"127.0.0.1", "localhost", "::1", "10.203.0.1", "robot.lan"} == allowed


def test_every_address_of_the_machine_is_allowed_when_bound_to_all() -> None:
    allowed = allowed_hosts("0.0.0.0")
    assert {"127.0.0.1", "localhost", "::1", socket.gethostname().lower()} <= allowed


@pytest.mark.parametrize("upgrade", [False, True], ids=["http", "websocket"])
def test_a_rebound_name_is_refused_and_the_log_says_how_to_allow_it(
    open_server: RunningServer, upgrade: bool, caplog: pytest.LogCaptureFixture
) -> None:
    path = "/ws" if upgrade else "/healthz"
    with caplog.at_level(logging.WARNING, logger="app.server.hosts"):
        assert status(open_server, "evil.example:80", path, upgrade) == (403 if upgrade else 400)
        assert status(open_server, "evil.example", path, upgrade) == (403 if upgrade else 400)
    (line,) = [r.getMessage() for r in caplog.records if r.name == "app.server.hosts"]
    assert "'evil.example'" in line and "AUTOPILOT_ALLOWED_HOSTS='[\"evil.example\"]'" in line
    port = open_server.url.rsplit(":", 1)[1]
    for name in ("127.0.0.1", "localhost", "[::1]", "robot.lan"):
        assert status(open_server, f"{name}:{port}", path, upgrade) == (101 if upgrade else 200)


def test_the_address_a_server_is_started_on_is_allowed() -> None:
    running = start_in_thread(Settings(), host="127.0.0.2")
    try:
        port = running.url.rsplit(":", 1)[1]
        assert status(running, f"127.0.0.2:{port}") == 200
        assert status(running, f"127.0.0.3:{port}") == 400
    finally:
        running.stop()


@pytest.fixture
def secured(start_server: Callable[[Settings], RunningServer]) -> Iterator[RunningServer]:
    yield start_server(Settings(secret=SECRET))


def test_with_a_secret_any_name_is_answered_its_token_decides(secured: RunningServer) -> None:
    assert status(secured, "evil.example") == 200
    assert status(secured, "evil.example", "/rosbridge", upgrade=True) == 101


def test_serve_s_host_option_is_a_name_the_server_answers() -> None:
    # `autopilot serve --host 172.30.0.10`, as the field lab starts it.
    settings = settings_from(argparse.Namespace(host="172.30.0.10", ros=None, robot=None))
    assert "172.30.0.10" in allowed_hosts(settings.host, settings.allowed_hosts)
