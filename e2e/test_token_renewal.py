"""Issue 37.4 in real browsers: with tokens of a short lifetime, the vehicle, relay and client
pages renew theirs before they expire (``renew`` on ``/ws``, the vehicle's rosbridge ``auth``
again) and stay in their room past several lifetimes, the vehicle's video and the goals flowing
over the same peer connections all along."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, Page, expect

from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from e2e.conftest import OpenRole
from e2e.helpers import heading_error, status, turtle_state, wait_for_live_video, wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]

SECRET = "token-renewal-e2e-test-secret"
ROOM = "renewing"
# Long enough for a page to load and log in with the token minted just before, on a machine
# loaded by the rest of the suite (a page took over 10 s there), short enough that the pages
# outlive several of them in a test.
LIFETIME_S = 20.0
# Each page renews after half of its token's time: this many renewals outlive 3 lifetimes.
RENEWALS = 6


@pytest.fixture
def server() -> Iterator[RunningServer]:
    """The module's server asks for tokens."""
    running = start_in_thread(Settings(environment="development", secret=SECRET, ice_servers=[]))
    yield running
    running.stop()


def _token(role: tokens.TokenRole, ttl_s: float = LIFETIME_S, room: str = ROOM) -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=ttl_s)


def _renewals(page: Page) -> int:
    return page.get_by_test_id("log").inner_text().count("token renewed")


def test_pages_renew_their_tokens_and_keep_their_room_and_media(
    server: RunningServer, open_role: OpenRole, browser: Browser, vehicle_browser: Browser
) -> None:
    query = {"room": ROOM, "auto": "1"}
    vehicle = open_role(
        "vehicle", vehicle_browser, token=_token("vehicle"), name="vehicle", **query
    )
    relay = open_role("relay", browser, token=_token("relay"), name="relay", **query)
    client = open_role("client", browser, token=_token("client"), name="client", **query)
    reader = _token("client", ttl_s=600, room="anywhere")  # the test's own, to read the turtle

    # The vehicle authenticated to /rosbridge: its spawn step turned turtle1 to face up.
    wait_until(
        lambda: heading_error(turtle_state(server, token=reader)["theta"], math.pi / 2) < 0.01,
        60,
        "the vehicle page's spawn step to turn the turtle to π/2",
    )
    start = client.get_by_role("button", name="Start Piloting")
    expect(start).to_be_enabled(timeout=120_000)
    start.click()
    expect(vehicle.get_by_test_id("goals-received")).not_to_have_text("0")

    wait_until(
        lambda: all(_renewals(page) >= RENEWALS for page in (vehicle, relay, client)),
        RENEWALS * LIFETIME_S + 60,
        f"every page to renew its token {RENEWALS} times",
    )
    # Still in the room, over the links made at the start: the relay received the vehicle's
    # video once, and goals and the client's video still flow.
    relay_status = status(relay)
    assert relay_status["vehicle"] == "vehicle" and relay_status["clients"] == ["client"]
    assert relay_status["vehicleTracks"] == 1
    goals = int(vehicle.get_by_test_id("goals-received").inner_text())
    wait_until(
        lambda: int(vehicle.get_by_test_id("goals-received").inner_text()) > goals,
        20,
        "more goals to reach the vehicle",
    )
    wait_for_live_video(client)
    # The vehicle's rosbridge session lived on with its renewed tokens: the goals turned the
    # turtle toward the face on the left, and the page never lost rosbridge.
    wait_until(
        lambda: heading_error(turtle_state(server, token=reader)["theta"], math.pi) < 0.3,
        60,
        "the turtle to turn toward the face on the left (θ ≈ π)",
    )
    assert status(vehicle)["rosConnected"] is True
    for page in (vehicle, relay, client):
        log = page.get_by_test_id("log").inner_text()
        assert "token expired" not in log and "unreachable" not in log
