"""The browser vehicle page drives the robot ``?robot=`` names (real Chromium, roslib.js, the
server's /rosbridge): a roslibpy stand-in plays a TurtleBot3 Burger, a relay page takes the
wheel, and what reaches the robot's /cmd_vel is of the type its rosapi names, within the
Burger's limits; its Odometry is the page's pose; the turtle is not touched."""

from __future__ import annotations

import json
from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, expect

from app.server.serve import RunningServer
from e2e.conftest import OpenRole
from e2e.helpers import FAKE_RELAY, status, turtle_state, wait_until
from tests.helpers.standin import POSITION, YAW, StandIn, velocities

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

# The operator's commands, sent on the fake relay's channel: mode, then drive commands.
TAKE_OVER = """() => window.fakeRelay.channel.send(
  JSON.stringify({ type: 'mode', mode: 'manual', operator: 'ann' }))"""
# The stick held: the page repeats the drive command every 0.1 s on a timer of its own, as the
# client page does (a repeat from the test's process would lapse past the dead-man's 0.3 s on a
# loaded machine, and the ramp would start again); let go: the timer stops, a stop is sent.
HOLD = """([linear, angular]) => {
  let seq = 0;
  const send = () => window.fakeRelay.channel.send(
    JSON.stringify({ type: 'drive', seq: ++seq, linear, angular }));
  send();
  window.held = { timer: setInterval(send, 100), next: () => ++seq };
}"""
LET_GO = """() => {
  clearInterval(window.held.timer);
  window.fakeRelay.channel.send(
    JSON.stringify({ type: 'drive', seq: window.held.next(), linear: 0, angular: 0 }));
}"""


@pytest.fixture
def rosbridge(server: RunningServer) -> str:
    return server.url.replace("http", "ws", 1) + "/rosbridge"


@pytest.fixture(params=["geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"])
def burger(request: pytest.FixtureRequest, rosbridge: str) -> Iterator[StandIn]:
    """A Burger whose bringup takes a Twist (as the preset says) or a TwistStamped on /cmd_vel."""
    robot = StandIn(rosbridge, ("/cmd_vel", request.param), "/odom")
    yield robot
    robot.close()


def test_the_vehicle_page_drives_a_burger(
    server: RunningServer,
    open_role: OpenRole,
    browser: Browser,
    vehicle_browser: Browser,
    burger: StandIn,
) -> None:
    room = "burger"
    vehicle = open_role(
        "vehicle", vehicle_browser, room=room, name="vehicle", auto="1", robot="turtlebot3"
    )
    expect(vehicle.get_by_test_id("robot")).to_contain_text("turtlebot3 (/cmd_vel, /odom)")
    # The Burger's odometry is the page's pose: its position, and the yaw of its quaternion.
    vehicle.wait_for_function("() => window.autopilotStatus.pose !== null", timeout=30_000)
    pose = status(vehicle)["pose"]
    assert (pose["x"], pose["y"], pose["theta"]) == pytest.approx((*POSITION, YAW))
    velocity_type = burger.velocity.message_type
    stamped = velocity_type.endswith("TwistStamped")
    assert status(vehicle)["velocityType"] == velocity_type

    def last() -> tuple[float, float] | None:
        commands = velocities(burger.commands(), stamped)
        return commands[-1][1:] if commands else None

    def at_top() -> bool:
        return last() == pytest.approx((0.22, -2.0))

    def stopped() -> bool:
        return last() == (0.0, 0.0)

    relay = browser.new_page()
    try:
        relay.goto(server.url + "/")
        relay.evaluate(FAKE_RELAY, {"wsUrl": server.ws_url, "room": room})
        relay.wait_for_function("() => window.fakeRelay.channel !== null", timeout=60_000)
        # Full stick ahead and to the right, held until the Burger gets its top speed and the
        # operator's 2 rad/s turn (however long the ramp takes on a loaded machine); then the
        # stick is let go.
        relay.evaluate(TAKE_OVER)
        relay.evaluate(HOLD, [1.0, -1.0])
        wait_until(at_top, 60, "the Burger's top speed and the operator's turn")
        relay.evaluate(LET_GO)
        wait_until(stopped, 20, "the released stick's stop at the robot")
    finally:
        relay.close()

    messages = [m for _, m in burger.commands()]
    shape = {"header", "twist"} if stamped else {"linear", "angular"}
    assert all(set(m) == shape for m in messages), json.dumps(messages[:3])
    if stamped:
        # ROS 2 (the server's flavour) spells a time sec and nanosec.
        assert all(set(m["header"]["stamp"]) == {"sec", "nanosec"} for m in messages)
    commands = velocities(burger.commands(), stamped)
    moving = [(v, w) for _, v, w in commands if v != 0.0 or w != 0.0]
    # Full stick on a Burger: its 0.22 m/s, reached by a ramp (2.5 m/s² from rest); the
    # operator's 2 rad/s turn; the stop at once.
    assert max(v for v, _ in moving) == pytest.approx(0.22)
    assert all(abs(v) <= 0.22 + 1e-12 and abs(w) <= 2.84 + 1e-12 for _, v, w in commands)
    assert moving[0][0] <= 2.5 * 0.05 + 1e-9
    assert min(w for _, w in moving) == pytest.approx(-2.0)
    assert commands[-1][1:] == (0.0, 0.0)
    # Nothing went to the turtle, and no spawn step turned it.
    turtle = turtle_state(server)
    assert (turtle["theta"], turtle["linear_velocity"]) == (0.0, 0.0)
    expect(vehicle.get_by_test_id("log")).not_to_contain_text("spawn step")


def test_an_unknown_robot_is_refused_on_the_page(
    server: RunningServer, open_role: OpenRole, vehicle_browser: Browser
) -> None:
    vehicle = open_role("vehicle", vehicle_browser, room="nobot", name="vehicle", robot="rover9")
    expect(vehicle.get_by_test_id("ros-state")).to_contain_text("no robot preset named 'rover9'")
    expect(vehicle.get_by_test_id("log")).to_contain_text("turtlesim, diffdrive, turtlebot3")
    assert status(vehicle)["rosConnected"] is False
