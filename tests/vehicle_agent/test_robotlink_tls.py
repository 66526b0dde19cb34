"""The agent's rosbridge link over wss:// with a token: the certificate is really checked."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from app.protocol import tokens
from app.server import tls
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from tests.vehicle_agent.test_robotlink import turn_and_stop
from vehicle_agent.cli import tls_context
from vehicle_agent.robotlink import RobotLinkError, RosbridgeLink
from vehicle_agent.rosbridge_client import RosbridgeClient

SECRET = "agent-rosbridge-tls-secret"


@pytest.fixture
def https_server(tmp_path: Path) -> Iterator[tuple[RunningServer, tls.TlsFiles]]:
    files = tls.self_signed(tmp_path)
    running = start_in_thread(Settings(secret=SECRET), tls_files=files)
    yield running, files
    # uvicorn stopped while a socket is still closing raises in its shutdown (InvalidState), so
    # let the client's close finish first.
    deadline = time.monotonic() + 5
    while running.server.server_state.connections and time.monotonic() < deadline:
        time.sleep(0.05)
    running.stop()


def wss_rosbridge(server: RunningServer) -> tuple[str, str]:
    """The server's ``wss://`` rosbridge URL and a vehicle token for it."""
    url = server.url.replace("https", "wss", 1) + "/rosbridge"
    return url, tokens.sign(SECRET, "any-room", "vehicle", now=time.time(), ttl_s=60)


async def test_a_vehicle_token_drives_over_verified_wss(
    https_server: tuple[RunningServer, tls.TlsFiles],
) -> None:
    server, files = https_server
    url, token = wss_rosbridge(server)
    link = RosbridgeLink(RosbridgeClient(url, token, tls_context(files.ca_file)))
    await turn_and_stop(link)


async def test_a_certificate_from_an_untrusted_ca_is_refused(
    https_server: tuple[RunningServer, tls.TlsFiles],
) -> None:
    # Without --ca-file the system's CAs are trusted, and the server's own CA is not one.
    server, _ = https_server
    url, token = wss_rosbridge(server)
    with pytest.raises(RobotLinkError, match="cannot connect to rosbridge.*not trusted"):
        await RosbridgeLink(RosbridgeClient(url, token)).start(lambda pose: None)
