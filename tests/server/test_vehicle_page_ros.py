"""The vehicle page learns its robot's ROS flavour from rosapi, in headless Chromium.

The server is started in each flavour; the page (roslib.js) asks its rosapi for the pose and
cmd_vel types, subscribes with them, and its spawn step (a teleport_absolute of that flavour)
turns the turtle to pi/2. The fallback rule is checked on the page's own module in
tests/protocol/test_robot_js.py.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import pytest
from playwright.async_api import Page

from app.protocol.ros import RosFlavour
from app.server.config import Settings
from app.server.serve import RunningServer

# One Chromium for the module, a context per test (tests/conftest.py), on the module's loop.
pytestmark = [
    pytest.mark.browser,
    pytest.mark.timeout(120),
    pytest.mark.asyncio(loop_scope="module"),
]

POSE_TYPE = {"1": "turtlesim/Pose", "2": "turtlesim/msg/Pose", "jazzy": "turtlesim_msgs/msg/Pose"}


@pytest.mark.parametrize("flavour", ["1", "2", "jazzy"])
async def test_vehicle_page_learns_the_flavour_and_drives(
    context_page: Page, start_server: Callable[[Settings], RunningServer], flavour: RosFlavour
) -> None:
    robot = start_server(Settings(environment="development", token=None, ros=flavour))
    # No ros= in the query: the page's setting is "auto".
    await context_page.goto(f"{robot.url}/vehicle?room=flavour-{flavour}")
    await context_page.wait_for_function(
        "() => { const s = window.autopilotStatus;"
        " return s.pose !== null && Math.abs(s.pose.theta - Math.PI / 2) < 1e-3; }",
        timeout=30_000,
    )
    status: dict[str, Any] = await context_page.evaluate("() => window.autopilotStatus")
    assert (status["rosFlavour"], status["rosTypesFrom"]) == (flavour, "robot")
    assert status["pose"]["theta"] == pytest.approx(math.pi / 2, abs=1e-3)
