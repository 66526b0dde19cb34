"""The browser vehicle with ``?profile=follow``: it drives to the standoff from the face."""

from __future__ import annotations

import math
import time

import pytest
from playwright.sync_api import Browser, expect

from app.protocol.control import PROFILES, TERRAIN_CENTRE
from app.server.serve import RunningServer
from e2e.conftest import OpenRole
from e2e.helpers import HEIGHT, WIDTH, status, turtle_state, wait_until
from vehicle_agent.core.control import pixel_to_terrain

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]


def test_the_vehicle_page_follows_the_face_and_the_client_draws_the_route(
    server: RunningServer, open_role: OpenRole, browser: Browser, vehicle_browser: Browser
) -> None:
    room = "follow"
    standoff = PROFILES["follow"].standoff_m
    # The fake camera's face is centred in the left third, on the middle row (e2e.helpers).
    face = pixel_to_terrain(WIDTH / 6, HEIGHT / 2, WIDTH, HEIGHT)
    vehicle = open_role("vehicle", vehicle_browser, room=room, name="vehicle", auto="1",
                        profile="follow")  # fmt: skip
    open_role("relay", browser, room=room, name="relay", auto="1", profile="follow")
    client = open_role("client", browser, room=room, name="client", auto="1")
    start = client.get_by_role("button", name="Start Piloting")
    expect(start).to_be_enabled(timeout=120_000)
    start.click()
    expect(vehicle.get_by_test_id("goals-received")).not_to_have_text("0", timeout=60_000)

    def off_standoff() -> float:
        turtle = turtle_state(server)
        return abs(math.hypot(turtle["x"] - face[0], turtle["y"] - face[1]) - standoff)

    wait_until(lambda: off_standoff() < 0.3, 60, "the turtle to reach its standoff from the face")
    time.sleep(1.0)  # and to hold it
    assert off_standoff() < 0.3
    turtle = turtle_state(server)
    size = 2 * TERRAIN_CENTRE
    assert 0 < turtle["x"] < size and 0 < turtle["y"] < size
    # It drove (from the centre to about 1 m right of the face): the route shows the way.
    assert status(vehicle)["lastTwist"] is not None
    driven = math.hypot(turtle["x"] - TERRAIN_CENTRE, turtle["y"] - TERRAIN_CENTRE)
    assert driven > 2.0
    wait_until(lambda: status(client)["routeM"] > 0.8 * driven, 20, "the client's route")
    expect(client.get_by_test_id("route")).to_contain_text("m driven")
