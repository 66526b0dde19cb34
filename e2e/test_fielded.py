"""Issue 9 fielded: the whole flow over HTTPS with per-room tokens, pages opened at the
non-loopback address 10.203.0.1, and a page from another site that cannot join or drive.

Needs the private network namespace (it binds 10.203.0.1):
``scripts/in-netns python3 -m pytest e2e/test_fielded.py``. Chromium trusts the server's
``--self-signed`` CA by pinning the CA's key, as ``autopilot relay --ca-file`` does.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser, ConsoleMessage, Page, Playwright, expect

from app.chromium import launch_options
from app.protocol import tokens
from app.server import tls
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from e2e.conftest import artifacts_dir
from e2e.helpers import heading_error, status, turtle_state, wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]

SERVER_ADDRESS = "10.203.0.1"  # scripts/in-netns: the namespace's non-loopback address
OTHER_ADDRESS = "10.203.0.2"  # where the foreign site is served from
SECRET = "fielded-e2e-test-secret-value"
ROOM = "fielded"


@pytest.fixture(scope="module")
def tls_files(tmp_path_factory: pytest.TempPathFactory) -> tls.TlsFiles:
    return tls.self_signed(tmp_path_factory.mktemp("tls"))


@pytest.fixture
def https_server(tls_files: tls.TlsFiles) -> Iterator[RunningServer]:
    settings = Settings(environment="production", secret=SECRET, ice_servers=[])
    running = start_in_thread(settings, host=SERVER_ADDRESS, tls_files=tls_files)
    yield running
    running.stop()


def _token(role: tokens.Role, room: str = ROOM) -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=600)


def _launch(playwright: Playwright, tls_files: tls.TlsFiles, fake_video: Path | None) -> Browser:
    assert tls_files.ca_file is not None
    return playwright.chromium.launch(**launch_options(fake_video, trust_ca=tls_files.ca_file))


def _turtle(server: RunningServer, tls_files: tls.TlsFiles) -> dict[str, Any]:
    """turtle1 from ``/turtlesim/state``, over verified HTTPS with a client token."""
    assert tls_files.ca_file is not None
    token = _token("client", room="anywhere")
    return turtle_state(server, token=token, ca_file=tls_files.ca_file)


class _Pages:
    """Opened pages, with their consoles kept for artifacts/."""

    def __init__(self) -> None:
        self.opened: list[tuple[str, Page, list[str]]] = []

    def open(self, name: str, browser: Browser, url: str) -> Page:
        context = browser.new_context(viewport={"width": 1280, "height": 960})
        context.set_default_timeout(60_000)
        page = context.new_page()
        console: list[str] = []

        def keep(message: ConsoleMessage) -> None:
            console.append(f"{message.type}: {message.text}")

        page.on("console", keep)
        page.on("worker", lambda worker: worker.on("console", keep))
        page.on("pageerror", lambda error: console.append(f"pageerror: {error}"))
        self.opened.append((name, page, console))
        page.goto(url)
        return page

    def keep_artifacts(self, request: pytest.FixtureRequest) -> None:
        folder = artifacts_dir(request)
        for name, page, console in self.opened:
            if not page.is_closed():
                page.screenshot(path=str(folder / f"{name}.png"), full_page=True)
            (folder / f"{name}.console.log").write_text("\n".join(console) + "\n")
            page.context.close()


@pytest.fixture
def pages(request: pytest.FixtureRequest) -> Iterator[_Pages]:
    opened = _Pages()
    yield opened
    opened.keep_artifacts(request)


def test_the_whole_flow_over_https_with_tokens_from_another_address(
    request: pytest.FixtureRequest,
    https_server: RunningServer,
    tls_files: tls.TlsFiles,
    playwright: Playwright,
    face_left_video: Path,
    pages: _Pages,
) -> None:
    base = https_server.url
    assert base == f"https://{SERVER_ADDRESS}:{base.rsplit(':', 1)[1]}"
    browser = _launch(playwright, tls_files, None)
    vehicle_browser = _launch(playwright, tls_files, face_left_video)
    try:
        vehicle = pages.open(
            "vehicle",
            vehicle_browser,
            f"{base}/vehicle?room={ROOM}&name=vehicle&auto=1#token={_token('vehicle')}",
        )
        # Issue 9: over plain HTTP from another address the page had no camera at all.
        assert vehicle.evaluate("() => window.isSecureContext") is True
        assert vehicle.evaluate("() => navigator.mediaDevices !== undefined") is True
        expect(vehicle.get_by_test_id("log")).to_contain_text("camera on", timeout=60_000)
        expect(vehicle.get_by_test_id("log")).to_contain_text(
            f"connected to wss://{SERVER_ADDRESS}"
        )
        pages.open(
            "relay", browser, f"{base}/relay?room={ROOM}&name=relay&auto=1#token={_token('relay')}"
        )
        client = pages.open(
            "client", browser, f"{base}/client?room={ROOM}&name=client#token={_token('client')}"
        )
        # The vehicle authenticated to /rosbridge with its token: its spawn step turned turtle1.
        wait_until(
            lambda: heading_error(_turtle(https_server, tls_files)["theta"], math.pi / 2) < 0.01,
            60,
            "the vehicle page's spawn step (a rosbridge service call) to turn the turtle to π/2",
        )
        client.get_by_role("button", name="Connect").click()
        client.get_by_role("button", name="Join Room").click()
        expect(client.get_by_test_id("log")).to_contain_text(f"joined room {ROOM} as client")
        start = client.get_by_role("button", name="Start Piloting")
        expect(start).to_be_enabled(timeout=120_000)
        start.click()
        expect(vehicle.get_by_test_id("goals-received")).not_to_have_text("0", timeout=60_000)
        # The face is on the left of the camera: the turtle turns from π/2 toward π.
        wait_until(
            lambda: heading_error(_turtle(https_server, tls_files)["theta"], math.pi) < 0.3,
            60,
            "the turtle to turn toward the face on the left (θ ≈ π)",
        )
        assert status(vehicle)["rosConnected"] is True
        client.screenshot(path=str(artifacts_dir(request) / "client-piloting.png"), full_page=True)
    finally:
        pages.keep_artifacts(request)
        pages.opened.clear()
        browser.close()
        vehicle_browser.close()


# A page on another site that knows the server's address and even holds a leaked vehicle token.
_FOREIGN_PAGE = """<!doctype html><meta charset="utf-8"><title>foreign</title><body><script>
const base = "wss://%(server)s";
const token = "%(token)s";
function attempt(path, first) {
  return new Promise((resolve) => {
    const ws = new WebSocket(base + path);
    let opened = false;
    ws.onopen = () => { opened = true; ws.send(JSON.stringify(first)); };
    ws.onclose = () => resolve({ path, opened });
    setTimeout(() => { ws.close(); resolve({ path, opened }); }, 5000);
  });
}
window.results = Promise.all([
  attempt("/ws", {type: "login", name: "intruder", role: "relay", room: "%(room)s", token}),
  attempt("/rosbridge", {op: "call_service", service: "/kill", args: {name: "turtle1"}, token}),
]);
</script></body>"""


@pytest.fixture
def foreign_site(https_server: RunningServer) -> Iterator[str]:
    """An HTTP site at another address serving :data:`_FOREIGN_PAGE`."""
    page = _FOREIGN_PAGE % {
        "server": https_server.url.split("://", 1)[1],
        "token": _token("vehicle"),
        "room": ROOM,
    }

    class Handler(BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            body = page.encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html; charset=utf-8")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, format: str, *args: Any) -> None:
            pass  # keep the test output to what matters

    site = ThreadingHTTPServer((OTHER_ADDRESS, 0), Handler)
    thread = threading.Thread(target=site.serve_forever, daemon=True)
    thread.start()
    yield f"http://{OTHER_ADDRESS}:{site.server_address[1]}/"
    site.shutdown()
    site.server_close()


def test_a_page_from_another_site_cannot_join_or_drive(
    https_server: RunningServer,
    tls_files: tls.TlsFiles,
    playwright: Playwright,
    foreign_site: str,
    pages: _Pages,
) -> None:
    before = _turtle(https_server, tls_files)
    browser = _launch(playwright, tls_files, None)
    try:
        page = pages.open("foreign", browser, foreign_site)
        results = page.evaluate("() => window.results")
        assert results == [
            {"path": "/ws", "opened": False},
            {"path": "/rosbridge", "opened": False},
        ]
    finally:
        browser.close()
        pages.opened.clear()
    after = _turtle(https_server, tls_files)
    assert after["name"] == "turtle1" and after["x"] == before["x"]


def test_an_https_vehicle_page_refuses_a_remote_ws_rosbridge_and_says_how_to_fix_it(
    https_server: RunningServer, tls_files: tls.TlsFiles, playwright: Playwright, pages: _Pages
) -> None:
    browser = _launch(playwright, tls_files, None)
    try:
        vehicle = pages.open(
            "vehicle",
            browser,
            f"{https_server.url}/vehicle?room={ROOM}&rosbridge=ws://{OTHER_ADDRESS}:9090"
            f"#token={_token('vehicle')}",
        )
        log = vehicle.get_by_test_id("log")
        expect(log).to_contain_text(f"refusing the rosbridge at ws://{OTHER_ADDRESS}:9090")
        expect(log).to_contain_text("ssl:=true certfile:=CERT keyfile:=KEY")
        assert status(vehicle)["rosConnected"] is False
    finally:
        browser.close()
        pages.opened.clear()
