"""The thesis flow: a face on the left of the vehicle's camera turns the turtle to the left."""

from __future__ import annotations

import math
import time

import pytest
from playwright.sync_api import Browser, expect

from app.server.serve import RunningServer
from e2e.conftest import OpenRole, artifacts_dir
from e2e.helpers import heading_error, status, turtle_state, wait_until

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]


@pytest.mark.parametrize("profile", ["default", "thesis"])
def test_face_on_the_left_turns_the_turtle_left_and_stop_stops_it(
    profile: str,
    request: pytest.FixtureRequest,
    server: RunningServer,
    open_role: OpenRole,
    browser: Browser,
    vehicle_browser: Browser,
) -> None:
    room = "thesis"
    query = {"room": room, "profile": profile}
    vehicle = open_role("vehicle", vehicle_browser, name="vehicle", auto="1", **query)
    open_role("relay", browser, name="relay", auto="1", **query)
    client = open_role("client", browser, name="client", room=room)

    # The vehicle's spawn step: the turtle starts at the centre, facing up (θ = π/2).
    wait_until(
        lambda: heading_error(turtle_state(server)["theta"], math.pi / 2) < 0.01,
        60,
        "the spawn step to turn the turtle to π/2",
    )

    client.get_by_role("button", name="Connect").click()
    client.get_by_role("button", name="Join Room").click()
    operation = client.get_by_label("Select Operation")
    expect(operation).to_be_enabled(timeout=120_000)  # filled from the relay's `ops`
    operation.select_option("face")
    client.get_by_role("button", name="Set Operation").click()
    expect(client.get_by_test_id("active-op")).to_have_text("face")
    client.get_by_role("button", name="Start Piloting").click()

    expect(vehicle.get_by_test_id("goals-received")).not_to_have_text("0", timeout=60_000)
    # The face sits in the left third of the frame, level with the turtle: the target lies
    # straight to the turtle's left on the terrain, so the heading goes from π/2 to about π.
    wait_until(
        lambda: heading_error(turtle_state(server)["theta"], math.pi) < 0.3,
        60,
        "the turtle to turn toward the face on the left (θ ≈ π)",
    )
    # The client's turtle view follows the same route from pose telemetry.
    wait_until(
        lambda: heading_error(status(client)["pose"]["theta"], math.pi) < 0.3,
        20,
        "the client's route to show the turtle facing left",
    )
    expect(client.get_by_test_id("goals-per-s")).not_to_have_text("–")
    client.screenshot(path=str(artifacts_dir(request) / "client-piloting.png"), full_page=True)

    client.get_by_role("button", name="Stop Piloting").click()
    expect(client.get_by_role("button", name="Start Piloting")).to_be_enabled(timeout=30_000)
    # Let goals and Twists already on the wire land, then nothing more may come.
    time.sleep(1.5)
    before = status(vehicle)
    theta_before = turtle_state(server)["theta"]
    time.sleep(2.5)
    after = status(vehicle)
    turtle = turtle_state(server)
    assert after["goalsReceived"] == before["goalsReceived"], "goals kept coming after Stop"
    assert after["twistsPublished"] == before["twistsPublished"], "Twists kept coming after Stop"
    assert after["lastTwist"]["angular"] == 0, "the last Twist was not a stop"
    assert turtle["angular_velocity"] == 0 and turtle["linear_velocity"] == 0
    assert abs(turtle["theta"] - theta_before) < 1e-9, "the turtle kept moving after Stop"


def test_an_unknown_operation_is_refused_and_the_current_one_stays(
    open_role: OpenRole, browser: Browser
) -> None:
    relay = open_role("relay", browser, room="ops", name="relay", auto="1")
    client = open_role("client", browser, room="ops", name="client", auto="1")
    operation = client.get_by_label("Select Operation")
    expect(operation).to_be_enabled(timeout=120_000)
    expect(client.get_by_test_id("active-op")).to_have_text("face")

    # A client offering an operation the relay does not have (an older or tampered page).
    operation.evaluate("select => select.add(new Option('No such thing', 'no-such-op'))")
    operation.select_option("no-such-op")
    client.get_by_role("button", name="Set Operation").click()

    expect(client.get_by_test_id("log")).to_contain_text('unknown operation "no-such-op"')
    expect(client.get_by_test_id("active-op")).to_have_text("face")
    assert status(relay)["op"] == "face"
