"""Issue 23, pages explain themselves: a refused token says why and how to get a new one (once),
a token put in the query is recognised, Leave Room is only enabled in a room, the vehicle page
over plain HTTP from another machine says why it has no camera, and the client says what the
frame tag is.

The plain-HTTP test binds 10.203.0.1, the private network namespace's non-loopback address
(``scripts/in-netns``): a page from loopback is a secure context and would get its camera.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest
from playwright.sync_api import Browser, ConsoleMessage, Page, expect

from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

SECRET = "page-messages-test-secret-value"
ROOM = "lab"
OTHER_ADDRESS = "10.203.0.1"  # scripts/in-netns: the namespace's non-loopback address


@pytest.fixture(scope="module")
def secret_server() -> Iterator[RunningServer]:
    """A server that admits only signed tokens."""
    running = start_in_thread(Settings(environment="development", secret=SECRET, ice_servers=[]))
    yield running
    running.stop()


def _token(role: tokens.Role = "client", room: str = ROOM, *, age_s: float = 0.0) -> str:
    return tokens.sign(SECRET, room, role, now=time.time() - age_s, ttl_s=60)


def _open(browser: Browser, url: str) -> tuple[Page, list[str]]:
    """A page in its own context, with its console lines."""
    page = browser.new_context().new_page()
    console: list[str] = []

    def keep(message: ConsoleMessage) -> None:
        console.append(message.text)

    page.on("console", keep)
    page.goto(url)
    return page, console


def _connect_and_join(page: Page) -> None:
    page.click("button[data-action=connect]")
    expect(page.get_by_test_id("state")).to_contain_text("connected, not in a room")
    page.click("button[data-action=join]")


# Each refused token, minted when its test runs (a token minted at collection could expire
# before a slow suite reaches it).
REFUSED: dict[str, Callable[[], str]] = {
    "expired": lambda: _token(age_s=120),
    "wrong role": lambda: _token("relay"),
    "wrong room": lambda: _token(room="elsewhere"),
    "malformed": lambda: "not-a-token",
}


@pytest.mark.parametrize("reason", list(REFUSED))
def test_a_refused_token_shows_why_and_how_to_get_a_new_one_logged_once(
    secret_server: RunningServer, browser: Browser, reason: str
) -> None:
    token = REFUSED[reason]()
    page, console = _open(browser, f"{secret_server.url}/client?room={ROOM}#token={token}")
    try:
        _connect_and_join(page)
        state = page.get_by_test_id("state")
        expect(state).to_contain_text(f"login refused: token refused: {reason}")
        remedy = f"get a new one with: autopilot token --room {ROOM} --role client"
        expect(state).to_contain_text(remedy)
        page.wait_for_timeout(300)  # a second report would arrive with the first
        assert sum(f"token refused: {reason}" in line for line in console) == 1, console
        expect(page.locator("button[data-action=leave]")).to_be_disabled()
    finally:
        page.context.close()


def test_a_token_in_the_query_is_recognised_and_sent_after_the_hash(
    secret_server: RunningServer, browser: Browser
) -> None:
    page, console = _open(browser, f"{secret_server.url}/client?room={ROOM}&token={_token()}")
    try:
        state = page.get_by_test_id("state")
        expect(state).to_contain_text("the token is in the query")
        expect(state).to_contain_text("put it after # instead")
        # Not used: the login goes without it, and the server says which token is missing.
        _connect_and_join(page)
        expect(state).to_contain_text("login refused: missing token")
        expect(state).to_contain_text(f"get one with: autopilot token --room {ROOM} --role client")
        assert sum("the token is in the query" in line for line in console) == 1, console
    finally:
        page.context.close()


def test_leave_room_is_enabled_only_in_a_room_and_the_client_explains_the_frame_tag(
    secret_server: RunningServer, browser: Browser
) -> None:
    page, _ = _open(browser, f"{secret_server.url}/client?room={ROOM}#token={_token()}")
    try:
        leave = page.locator("button[data-action=leave]")
        expect(leave).to_be_disabled()
        _connect_and_join(page)
        expect(page.get_by_test_id("state")).to_contain_text(f"joined room {ROOM}")
        expect(leave).to_be_enabled()
        leave.click()
        expect(page.get_by_test_id("state")).to_contain_text("disconnected")
        expect(leave).to_be_disabled()
        expect(page.get_by_test_id("frame-tag-note")).to_contain_text("frame tag")
        expect(page.get_by_test_id("frame-tag-note")).to_be_visible()
    finally:
        page.context.close()


def test_the_vehicle_page_over_plain_http_from_another_machine_says_why_there_is_no_camera(
    browser: Browser,
) -> None:
    settings = Settings(environment="development", token=None, ice_servers=[])
    running = start_in_thread(settings, host=OTHER_ADDRESS)
    page, console = _open(browser, f"{running.url}/vehicle?room={ROOM}")
    try:
        camera = page.get_by_test_id("camera-state")
        expect(camera).to_contain_text("browsers give the camera only to pages served over HTTPS")
        expect(camera).to_contain_text("docs/deploying.md")
        assert not any("TypeError" in line for line in console), console
    finally:
        page.context.close()
        running.stop()


def test_the_vehicle_page_on_loopback_has_its_camera(
    secret_server: RunningServer, browser: Browser
) -> None:
    """The other side of the HTTP check: a secure context gets the (fake) camera."""
    page, _ = _open(browser, f"{secret_server.url}/vehicle?room={ROOM}")
    try:
        expect(page.get_by_test_id("camera-state")).to_contain_text("camera on: 640×480")
    finally:
        page.context.close()
