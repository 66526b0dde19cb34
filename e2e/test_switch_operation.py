"""Adaptivity mid-flight: switching face -> fire turns the turtle from the face to the flame."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import cv2
import pytest
from playwright.sync_api import Browser, Playwright, expect

from app.chromium import launch_options
from app.server.serve import RunningServer
from e2e.conftest import OpenRole, artifacts_dir
from e2e.helpers import (
    FPS,
    HEIGHT,
    WIDTH,
    face_frame,
    heading_error,
    status,
    turtle_state,
    wait_until,
    write_y4m,
)

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]


@pytest.fixture(scope="module")
def face_left_flame_right(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The fake camera: a face in the left third, a flame-coloured blob in the right third."""
    frame = face_frame("obama.jpg", "left")
    centre = (WIDTH * 5 // 6, HEIGHT // 2)
    cv2.ellipse(frame, centre, (50, 70), 0, 0, 360, (0, 90, 255), -1)  # orange (BGR)
    cv2.ellipse(frame, (centre[0], centre[1] + 15), (25, 35), 0, 0, 360, (40, 210, 255), -1)
    path = tmp_path_factory.mktemp("switch") / "face-left-flame-right.y4m"
    write_y4m(path, frame, frames=2 * FPS)
    return path


@pytest.fixture(scope="module")
def scene_browser(playwright: Playwright, face_left_flame_right: Path) -> Iterator[Browser]:
    launched = playwright.chromium.launch(**launch_options(face_left_flame_right))
    yield launched
    launched.close()


def test_switching_face_to_fire_turns_the_turtle_to_the_flame(
    request: pytest.FixtureRequest,
    server: RunningServer,
    open_role: OpenRole,
    browser: Browser,
    scene_browser: Browser,
) -> None:
    query = {"room": "switch", "auto": "1"}
    vehicle = open_role("vehicle", scene_browser, name="vehicle", **query)
    relay = open_role("relay", browser, name="relay", **query)
    client = open_role("client", browser, name="client", **query)

    operation = client.get_by_label("Select Operation")
    expect(operation).to_be_enabled(timeout=120_000)
    operation.select_option("face")
    client.get_by_role("button", name="Set Operation").click()
    expect(client.get_by_test_id("active-op")).to_have_text("face")
    client.get_by_role("button", name="Start Piloting").click()

    # The face is level with the turtle on the left: heading about π.
    wait_until(
        lambda: heading_error(turtle_state(server)["theta"], math.pi) < 0.3,
        90,
        "the turtle to turn toward the face on the left (θ ≈ π)",
    )
    assert status(vehicle)["lastGoal"]["op"] == "face"

    # Switch while piloting, without stopping: the flame on the right wins, heading about 0.
    operation.select_option("fire")
    client.get_by_role("button", name="Set Operation").click()
    expect(client.get_by_test_id("active-op")).to_have_text("fire", timeout=30_000)
    expect(client.get_by_test_id("log")).to_contain_text("operation is now fire")
    wait_until(
        lambda: heading_error(turtle_state(server)["theta"], 0.0) < 0.3,
        60,
        "the turtle to turn toward the flame on the right (θ ≈ 0)",
    )
    assert status(vehicle)["lastGoal"]["op"] == "fire"
    assert status(relay)["op"] == "fire" and status(relay)["piloting"] is True
    client.screenshot(path=str(artifacts_dir(request) / "client-fire.png"), full_page=True)
