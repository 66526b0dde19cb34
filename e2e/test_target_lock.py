"""Target lock end to end: the client clicks the smaller of two faces and the goals follow it;
Unlock brings them back to the larger one; switching the operation releases the lock and says so.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import pytest
from playwright.sync_api import Browser, Page, Playwright, expect

from app.chromium import launch_options
from app.tools.bench.lock import click_position
from app.vision.lock import contains
from app.vision.window import Box
from e2e.conftest import OpenRole, open_room
from e2e.helpers import FPS, HEIGHT, WIDTH, status, wait_until, write_y4m
from vehicle_agent.video import TwoFaceVideo

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]

# The scene's faces as the Python reference finds them in its first frame are about 130 and
# 76 pixels wide; a goal within this many pixels of a face's centre is on that face.
ON_FACE_PX = 40


@pytest.fixture(scope="module")
def scene() -> TwoFaceVideo:
    return TwoFaceVideo(WIDTH, HEIGHT, FPS)


@pytest.fixture(scope="module")
def two_faces_browser(
    playwright: Playwright, scene: TwoFaceVideo, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[Browser]:
    """Chromium whose camera shows the two-face scene's first frame."""
    path: Path = tmp_path_factory.mktemp("lock") / "two-faces.y4m"
    write_y4m(path, cv2.cvtColor(scene.render(0), cv2.COLOR_RGB2BGR), frames=2 * FPS)
    launched = playwright.chromium.launch(**launch_options(path))
    yield launched
    launched.close()


def goal_near(vehicle: Page, centre: tuple[float, float]) -> bool:
    goal = status(vehicle)["lastGoal"]
    return goal is not None and abs(goal["x"] - centre[0]) + abs(goal["y"] - centre[1]) < ON_FACE_PX


def click_frame_point(client: Page, x: float, y: float) -> None:
    """Click the client's video where frame pixel (x, y) is shown."""
    video = client.get_by_test_id("video")
    box = video.bounding_box()
    assert box is not None
    px, py = click_position(box["width"], box["height"], x, y)
    video.click(position={"x": px, "y": py})


def test_click_the_smaller_face_then_unlock(
    open_role: OpenRole, browser: Browser, two_faces_browser: Browser, scene: TwoFaceVideo
) -> None:
    vehicle, _, client = open_room(open_role, "lock", two_faces_browser, browser, "client")
    large, small = scene.face_centre(0), scene.small_centre(0)

    start = client.get_by_role("button", name="Start Piloting")
    expect(start).to_be_enabled(timeout=120_000)
    start.click()
    wait_until(lambda: goal_near(vehicle, large), 90, "goals on the larger face (the default)")
    # Both faces are on show, so a click lands on a box the relay found.
    wait_until(lambda: len(status(client)["lastDetections"]["boxes"]) == 2, 30, "two face boxes")

    click_frame_point(client, *small)
    lock_state = client.get_by_test_id("lock-state")
    expect(lock_state).to_have_text("locked", timeout=10_000)
    locked: Box = tuple(status(client)["lock"]["box"])  # type: ignore[assignment]
    assert contains(locked, *small) and not contains(locked, *large)
    wait_until(lambda: goal_near(vehicle, small), 30, "goals on the smaller face once locked")
    detections = status(client)["lastDetections"]
    assert detections["locked"] is not None and contains(tuple(detections["locked"]), *small)

    client.get_by_role("button", name="Unlock").click()
    expect(lock_state).to_contain_text("no lock", timeout=10_000)
    wait_until(lambda: goal_near(vehicle, large), 30, "goals back on the larger face")

    # Switching the operation releases a lock, and the client says why.
    click_frame_point(client, *small)
    expect(lock_state).to_have_text("locked", timeout=10_000)
    client.get_by_label("Select Operation").select_option("fire")
    client.get_by_role("button", name="Set Operation").click()
    expect(lock_state).to_contain_text("operation changed to fire", timeout=10_000)
    expect(client.get_by_role("button", name="Unlock")).to_be_disabled()
