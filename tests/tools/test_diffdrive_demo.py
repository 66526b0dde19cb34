"""``autopilot demo --robot diffdrive`` end to end in the browser: the server's room with its
diffdrive robot, the agent driving it through ``/rosbridge`` by its description, the relay
finding a face in the agent's video, and the client page showing the room's map, the robot where
its odometry puts it, and the robot moving once piloting starts.

Run inside the private network namespace, as the other demo tests.
"""

from __future__ import annotations

import math
import signal
import socket
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from queue import Queue
from typing import Any

import pytest
from playwright.sync_api import Page, sync_playwright

from app.chromium import launch_options
from app.diffdrive.room import ROOM
from tests.helpers.processes import descendants, wait_all_gone
from tests.helpers.waiting import wait_until
from tests.tools.test_demo import wait_for_line, with_suppressed_kill

pytestmark = [pytest.mark.browser, pytest.mark.e2e, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
# Generous: the demo starts Chromium for its relay and the machine is shared; every wait ends
# as soon as its condition holds.
START_S = 120.0
WAIT_S = 60.0
# The robot's colour on the map (roomview.js).
ROBOT = (0x2F, 0x6F, 0xD0)


@pytest.fixture
def demo(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[str], Queue[str]]]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    argv = [sys.executable, "-m", "app.cli", "demo", "--robot", "diffdrive", "--port", str(port)]
    process = subprocess.Popen(
        [*argv, "--state-dir", str(tmp_path)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines: Queue[str] = Queue()

    def pump() -> None:
        assert process.stdout is not None
        for line in process.stdout:
            lines.put(line)

    threading.Thread(target=pump, daemon=True).start()
    try:
        yield process, lines
    finally:
        if process.poll() is None:
            for pid in descendants(process.pid):
                with_suppressed_kill(pid)
            process.kill()
        process.wait(timeout=30)
        assert process.stdout is not None
        process.stdout.close()


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


def pixel(page: Page, x: float, y: float) -> tuple[int, int, int]:
    """The map canvas's colour at room point (x, y) metres."""
    rgb: list[int] = page.evaluate(
        """([x, y, width]) => {
            const canvas = document.querySelector('[data-testid="turtle-view"]');
            const scale = canvas.width / width;
            const at = [Math.round(x * scale), Math.round(canvas.height - y * scale)];
            return Array.from(canvas.getContext('2d').getImageData(...at, 1, 1).data.slice(0, 3));
        }""",
        [x, y, ROOM.width],
    )
    return rgb[0], rgb[1], rgb[2]


def ahead(pose: dict[str, float], distance: float, bearing: float) -> tuple[float, float]:
    """The room point ``distance`` metres from the robot at ``bearing`` from its heading."""
    heading = pose["theta"] + bearing
    return pose["x"] + distance * math.cos(heading), pose["y"] + distance * math.sin(heading)


def test_the_diffdrive_demo_drives_the_rooms_robot(
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
            # The map is the room's, its billboards where the server's room has them.
            wait_until(lambda: status(page)["billboards"] is not None, WAIT_S, "the room's map")
            assert set(status(page)["billboards"]) == {b.name for b in ROOM.billboards}
            # The robot's odometry reaches the map: it stands at the room's start.
            wait_until(lambda: status(page)["poses"] > 0, WAIT_S, "the robot's pose")
            start = status(page)["pose"]
            assert (start["x"], start["y"]) == pytest.approx((ROOM.start.x, ROOM.start.y), abs=0.05)
            # The map draws it there (roomview.js's robot blue beside its heading line), and
            # its camera's wedge ahead of it (the floor tinted yellow), not behind it.
            assert pixel(page, *ahead(start, 0.1, math.pi / 2)) == ROBOT
            wedge, behind = (
                pixel(page, *ahead(start, 1.0, 0.3)),
                pixel(page, *ahead(start, 0.5, 3.0)),
            )
            assert wedge[0] - wedge[2] > behind[0] - behind[2] + 20, (wedge, behind)
            page.get_by_role("button", name="Start Piloting").click()
            # The relay finds a face in the agent's video, and the goals it sends drive the
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
