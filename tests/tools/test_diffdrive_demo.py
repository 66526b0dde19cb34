"""``autopilot demo --robot diffdrive --profile onboard`` end to end in the browser: the
server's arena with its diffdrive robot, the agent filming through the robot's own camera topic and
driving it through ``/rosbridge`` by its description, the relay finding a face in that video, and
the client page showing the camera's video, the arena's map, the robot where its odometry puts it,
and the robot moving once piloting starts.

Run inside the private network namespace, as the other demo tests.
"""

from __future__ import annotations

import math
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path
from queue import Queue
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from playwright.sync_api import Page, sync_playwright

from app.chromium import launch_options
from app.diffdrive.arena import ARENA
from app.diffdrive.camera import Pinhole, Renderer, encode_jpeg
from app.diffdrive.robot import CAMERA_HFOV
from app.diffdrive.sim import ArenaSim
from tests.helpers.demo import running_demo, wait_for_line
from tests.helpers.processes import descendants, wait_all_gone
from tests.helpers.waiting import wait_until

pytestmark = [pytest.mark.browser, pytest.mark.e2e, pytest.mark.slow]

# Generous: the demo starts Chromium for its relay and the machine is shared; every wait ends
# as soon as its condition holds.
START_S = 120.0
WAIT_S = 60.0
# The robot's colour on the map (arenaview.js).
ROBOT = (0x2F, 0x6F, 0xD0)
CAMERA = Pinhole(hfov=CAMERA_HFOV)
# The strips of the camera's frame compared (rows, from and to): the ceiling below the frame
# tag the agent stamps on the top 16 rows, and the floor just in front of the robot.
CEILING_ROWS = (24, 40)
FLOOR_ROWS = (456, 472)
# How far the video's colours may be from the camera's frame, after its JPEG and the two
# WebRTC encodes (per channel, 0 to 255).
COLOUR_TOLERANCE = 12.0


@pytest.fixture
def demo(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Queue[str]]]:
    args = ["--robot", "diffdrive", "--profile", "onboard", "--state-dir", str(tmp_path)]
    with running_demo(args) as running:
        yield running


def status(page: Page) -> dict[str, Any]:
    found: dict[str, Any] = page.evaluate(
        """() => {
            const s = window.autopilotStatus;
            return {pose: s.pose, poses: s.poses, detections: s.detections,
                    target: s.lastDetections?.target ?? null, w: s.lastDetections?.w,
                    billboards: s.billboards};
        }"""
    )
    return found


def strips(page: Page) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
    """The client's video frame, drawn at the camera's size (the video may arrive smaller): the
    median colour (RGB) of the ceiling's and the floor's strips; None before the video plays."""
    found: dict[str, list[int]] | None = page.evaluate(
        """([width, height, ceiling, floor]) => {
            const video = document.querySelector('video');
            if (!video.videoWidth) return null;
            const canvas = Object.assign(document.createElement('canvas'), { width, height });
            const ctx = canvas.getContext('2d');
            ctx.drawImage(video, 0, 0, width, height);
            const rows = ([from, to]) =>
                Array.from(ctx.getImageData(0, from, width, to - from).data);
            return { ceiling: rows(ceiling), floor: rows(floor) };
        }""",
        [CAMERA.width, CAMERA.height, CEILING_ROWS, FLOOR_ROWS],
    )
    if found is None:
        return None
    rgba = {name: np.array(values, np.float64).reshape(-1, 4) for name, values in found.items()}
    return np.median(rgba["ceiling"][:, :3], axis=0), np.median(rgba["floor"][:, :3], axis=0)


def expected_strips() -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The same medians of the robot camera's frame at the arena's start, as the server sends it
    (JPEG): the ceiling and the floor look the same from any pose away from the walls."""
    renderer = Renderer(ARENA, CAMERA)
    jpeg = encode_jpeg(renderer.render(ArenaSim().scene()))
    bgr = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR)
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB).astype(np.float64)

    def median(rows: tuple[int, int]) -> npt.NDArray[np.float64]:
        return np.median(rgb[rows[0] : rows[1]].reshape(-1, 3), axis=0)

    return median(CEILING_ROWS), median(FLOOR_ROWS)


def pixel(page: Page, x: float, y: float) -> tuple[int, int, int]:
    """The map canvas's colour at arena point (x, y) metres."""
    rgb: list[int] = page.evaluate(
        """([x, y, width]) => {
            const canvas = document.querySelector('[data-testid="turtle-view"]');
            const scale = canvas.width / width;
            const at = [Math.round(x * scale), Math.round(canvas.height - y * scale)];
            return Array.from(canvas.getContext('2d').getImageData(...at, 1, 1).data.slice(0, 3));
        }""",
        [x, y, ARENA.width],
    )
    return rgb[0], rgb[1], rgb[2]


def ahead(pose: dict[str, float], distance: float, bearing: float) -> tuple[float, float]:
    """The arena point ``distance`` metres from the robot at ``bearing`` from its heading."""
    heading = pose["theta"] + bearing
    return pose["x"] + distance * math.cos(heading), pose["y"] + distance * math.sin(heading)


def test_the_diffdrive_demo_drives_the_arenas_robot_from_its_own_camera(
    demo: tuple[subprocess.Popen[str], Queue[str]],
) -> None:
    process, lines = demo
    url = wait_for_line(lines, r"(http://\S+/client\?room=default#token=\S+)", START_S).group(1)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(**launch_options())
        try:
            page = browser.new_page()
            page.goto(url)
            page.get_by_role("button", name="Connect").click()
            page.wait_for_function(
                "() => !document.querySelector('[data-action=join]').disabled", timeout=30_000
            )
            page.get_by_role("button", name="Join Room").click()
            page.wait_for_function(
                "() => !document.querySelector('[data-action=start]').disabled",
                timeout=START_S * 1000,
            )
            # The video the client sees is the robot's own camera: its ceiling and floor.
            ceiling, floor = expected_strips()
            wait_until(lambda: strips(page) is not None, WAIT_S, "the robot's video")
            shown = strips(page)
            assert shown is not None
            assert list(shown[0]) == pytest.approx(list(ceiling), abs=COLOUR_TOLERANCE), shown
            assert list(shown[1]) == pytest.approx(list(floor), abs=COLOUR_TOLERANCE), shown
            # The map is the arena's, its billboards where the server's arena has them.
            wait_until(lambda: status(page)["billboards"] is not None, WAIT_S, "the arena's map")
            assert set(status(page)["billboards"]) == {b.name for b in ARENA.billboards}
            # The robot's odometry reaches the map: it stands at the arena's start.
            wait_until(lambda: status(page)["poses"] > 0, WAIT_S, "the robot's pose")
            start = status(page)["pose"]
            assert (start["x"], start["y"]) == pytest.approx(
                (ARENA.start.x, ARENA.start.y), abs=0.05
            )
            # The map draws it there (arenaview.js's robot blue beside its heading line), and
            # its camera's wedge ahead of it (the floor tinted yellow), not behind it.
            assert pixel(page, *ahead(start, 0.1, math.pi / 2)) == ROBOT
            wedge, behind = (
                pixel(page, *ahead(start, 1.0, 0.3)),
                pixel(page, *ahead(start, 0.5, 3.0)),
            )
            assert wedge[0] - wedge[2] > behind[0] - behind[2] + 20, (wedge, behind)
            page.get_by_role("button", name="Start Piloting").click()
            # The relay finds a face in the robot's camera, and the goals it sends drive the
            # robot through /rosbridge.
            wait_until(lambda: status(page)["target"] is not None, WAIT_S, "a target")

            def moved() -> bool:
                pose = status(page)["pose"]
                turned = abs(math.remainder(pose["theta"] - start["theta"], math.tau))
                return math.dist((pose["x"], pose["y"]), (start["x"], start["y"])) > 0.2 or (
                    turned > 0.3
                )

            wait_until(moved, WAIT_S, "the robot moving once piloting started")
        finally:
            browser.close()

    children = descendants(process.pid)
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=60) == 0
    assert wait_all_gone(children) == []
