"""``autopilot vehicle --robot NAME|FILE`` drives the robot a description names, through the
server's /rosbridge: a roslibpy stand-in plays the robot (its Odometry out, its velocity topic in,
as a TurtleBot's bringup would), a Python relay takes the wheel, and the commands that reach the
robot are of the described (or reported) type, on the described topic, within its limits."""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import pytest

from app.server.serve import RunningServer
from tests.helpers.standin import POSITION, YAW, StandIn, velocities

from .pyrelay import PyRelay

pytestmark = [pytest.mark.timeout(120)]

WAIT_S = 10.0

ROVER = """
name = "rover"

[velocity]
topic = "/rover/base/cmd_vel"
type = "geometry_msgs/TwistStamped"
frame_id = "rover_base"

[pose]
topic = "/rover/odom"
type = "nav_msgs/Odometry"

[camera]
topic = "/rover/camera/image_raw"
type = "sensor_msgs/Image"
hfov_deg = 70.0

[limits]
max_linear = 0.3
max_angular = 0.5
linear_accel = 1.0
angular_accel = 2.0
"""


@contextlib.asynccontextmanager
async def stand_in(url: str, velocity: tuple[str, str], odom: str) -> AsyncIterator[StandIn]:
    robot = await asyncio.to_thread(StandIn, url, velocity, odom)
    try:
        yield robot
    finally:
        await asyncio.to_thread(robot.close)


@contextlib.contextmanager
def agent(
    server: RunningServer, robot: str, log: Path, video: str
) -> Iterator[subprocess.Popen[bytes]]:
    """``autopilot vehicle --robot ROBOT --video VIDEO`` on the server's /rosbridge, logging to
    ``log``."""
    rosbridge = server.url.replace("http", "ws", 1) + "/rosbridge"
    with log.open("wb") as out:
        process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "app.cli",
                "vehicle",
                "--server",
                server.url,
                "--rosbridge",
                rosbridge,
                "--robot",
                robot,
                "--video",
                video,
                "--size",
                "160x120",
                "--fps",
                "5",
            ],
            stdout=out,
            stderr=subprocess.STDOUT,
        )
        try:
            yield process
        finally:
            process.terminate()
            process.wait(timeout=20)


async def operator_drives(
    relay: PyRelay, standin: StandIn, stamped: bool, top: tuple[float, float]
) -> None:
    """The operator holds full stick ahead and to the right (a command every 0.1 s, as a page
    repeats it) until the robot gets ``top`` (its full speed, however long the ramp takes on a
    loaded machine), then lets go."""
    relay.send({"type": "mode", "mode": "manual", "operator": "ann"})
    seq = 0

    def at_top() -> bool:
        commands = velocities(standin.commands(), stamped)
        return bool(commands) and commands[-1][1:] == pytest.approx(top)

    async with asyncio.timeout(30):
        while not at_top():
            seq += 1
            relay.send({"type": "drive", "seq": seq, "linear": 1.0, "angular": -1.0})
            await asyncio.sleep(0.1)
    relay.send({"type": "drive", "seq": seq + 1, "linear": 0.0, "angular": 0.0})


async def drive_and_collect(
    server: RunningServer,
    robot: str,
    velocity: tuple[str, str],
    odom: str,
    log: Path,
    top: tuple[float, float],
    video: str = "synthetic",
) -> tuple[StandIn, PyRelay, float]:
    """Drive ``robot`` by hand to its ``top`` speed and let go; the stand-in, the relay, and
    the server's count of open /rosbridge sessions while the agent drove."""
    url = server.url.replace("http", "ws", 1) + "/rosbridge"
    async with stand_in(url, velocity, odom) as standin:
        relay = PyRelay(server.ws_url)
        await relay.start()
        try:
            with agent(server, robot, log, video):
                await relay.until(
                    lambda: relay.channel is not None and relay.channel.readyState == "open", 60
                )
                # The agent reads the robot's pose from its Odometry and reports it.
                await relay.until(lambda: any(m["type"] == "pose" for m in relay.messages), 30)
                # The server samples its sessions once a second: a sample taken from now on.
                await asyncio.sleep(1.5)
                sessions = server.metrics.registry.get_sample_value("autopilot_rosbridge_sessions")
                stamped = velocity[1].endswith("TwistStamped")
                await operator_drives(relay, standin, stamped, top)

                def stopped() -> bool:
                    return velocities(standin.commands(), stamped)[-1][1:] == (0.0, 0.0)

                await relay.until(stopped, 10)
        finally:
            await relay.leave()
        assert sessions is not None
        return standin, relay, sessions


def reported_pose(relay: PyRelay) -> dict[str, Any]:
    return next(m for m in relay.messages if m["type"] == "pose")


async def test_a_burger_gets_twists_on_cmd_vel_within_its_limits(
    server: RunningServer, tmp_path: Path
) -> None:
    log = tmp_path / "agent.log"
    # Full stick on a Burger: its top speed ahead, the operator's 2 rad/s turn.
    velocity = ("/cmd_vel", "geometry_msgs/msg/Twist")
    standin, relay, _ = await drive_and_collect(
        server, "turtlebot3", velocity, "/odom", log, (0.22, -2.0)
    )
    output = log.read_text()
    pose = reported_pose(relay)
    # Odometry's position, and the yaw of its (non-unit) quaternion.
    assert (pose["x"], pose["y"], pose["theta"]) == pytest.approx((*POSITION, YAW)), output
    commands = velocities(standin.commands(), stamped=False)
    assert all(set(m) == {"linear", "angular"} for _, m in standin.commands())
    # A Burger: never beyond 0.22 m/s; full stick is its top speed, reached by a ramp: the first
    # step from rest is at most one 50 ms tick of its 2.5 m/s² and 3.2 rad/s².
    moving = [(at, v, w) for at, v, w in commands if v != 0.0 or w != 0.0]
    assert max(v for _, v, _ in moving) == pytest.approx(0.22), output
    assert all(abs(v) <= 0.22 and abs(w) <= 2.84 for _, v, w in commands)
    assert moving[0][1] <= 2.5 * 0.05 + 1e-9, output
    assert moving[0][2] >= -3.2 * 0.05 - 1e-9, output
    assert min(w for _, _, w in moving) == pytest.approx(-2.0)  # the operator's 2 rad/s
    # Letting go stops it, at once.
    assert commands[-1][1:] == (0.0, 0.0)
    # No turtlesim here: the spawn step is not tried.
    assert "spawn step" not in output


async def test_a_robot_file_with_twist_stamped(server: RunningServer, tmp_path: Path) -> None:
    description = tmp_path / "rover.toml"
    description.write_text(ROVER, encoding="utf-8")
    log = tmp_path / "agent.log"
    velocity = ("/rover/base/cmd_vel", "geometry_msgs/msg/TwistStamped")
    before = time.time()
    # Its camera is the one the file names (`--video ros`), of the type it names while the
    # robot's rosapi cannot say (nobody publishes it yet).
    standin, relay, sessions = await drive_and_collect(
        server, str(description), velocity, "/rover/odom", log, (0.3, -0.5), video="ros"
    )
    output = log.read_text()
    # The stand-in's session and the agent's one: its camera rides on the robot's connection.
    assert sessions == 2, output
    assert "camera /rover/camera/image_raw: sensor_msgs/Image (from the robot's description)" in (
        output
    ), output
    assert reported_pose(relay)["theta"] == pytest.approx(YAW), output
    messages = [m for _, m in standin.commands()]
    assert messages, output
    for message in messages:
        header = message["header"]
        # ROS 2's time (the server's flavour), the wall clock's, in the file's frame.
        stamp = header["stamp"]["sec"] + header["stamp"]["nanosec"] / 1e9
        assert before <= stamp <= time.time() + 1, message
        assert header["frame_id"] == "rover_base"
    commands = velocities(standin.commands(), stamped=True)
    assert max(v for _, v, _ in commands) == pytest.approx(0.3), output
    assert min(w for _, _, w in commands) == pytest.approx(-0.5), output
    assert commands[-1][1:] == (0.0, 0.0)


async def test_the_type_the_robot_reports_beats_the_description(
    server: RunningServer, tmp_path: Path
) -> None:
    # A Burger whose bringup takes TwistStamped on /cmd_vel (the preset says Twist): rosapi
    # names the type, and the agent publishes what the robot takes.
    log = tmp_path / "agent.log"
    velocity = ("/cmd_vel", "geometry_msgs/msg/TwistStamped")
    standin, _, _ = await drive_and_collect(
        server, "turtlebot3", velocity, "/odom", log, (0.22, -2.0)
    )
    output = log.read_text()
    messages = [m for _, m in standin.commands()]
    assert messages and all({"header", "twist"} == set(m) for m in messages), output
    assert "is a geometry_msgs/TwistStamped on the robot" in output
    assert max(v for _, v, _ in velocities(standin.commands(), stamped=True)) == pytest.approx(0.22)
