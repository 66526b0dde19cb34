"""Bad input on the command line: one line naming the problem, non-zero exit, no traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from app.server.serve import RunningServer


def autopilot(
    *args: str, timeout: float = 60, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``autopilot`` with ``args``; ``env`` adds to this process's environment."""
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        env=None if env is None else {**os.environ, **env},
    )


def assert_one_line_error(result: subprocess.CompletedProcess[str], *needles: str) -> None:
    output = result.stdout + result.stderr
    assert result.returncode != 0, output
    assert "Traceback" not in output, output
    errors = [line for line in output.splitlines() if "ERROR" in line or "error:" in line]
    assert len(errors) == 1, output
    for needle in needles:
        assert needle in errors[0], output


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--server", "http://127.0.0.1:9"], ["signaling server", "127.0.0.1:9"]),
        (["--server", "not-a-url"], ["server URL", "not-a-url"]),
        (["--video", "/no/such/clip.mp4"], ["no such video file", "/no/such/clip.mp4"]),
        (["--video", "/dev/video99"], ["no such video device", "/dev/video99"]),
        (["--rosbridge", "ws://127.0.0.1:9"], ["rosbridge", "ws://127.0.0.1:9", "refused"]),
        (["--rosbridge", "robot:9090"], ["rosbridge URL", "robot:9090"]),
        (["--size", "big"], ["size", "big"]),
        (["--size", "641x480"], ["size", "641x480"]),
        (["--profile", "fastest"], ["fastest"]),
        # float() takes these, but a NaN goal timeout would never expire.
        (["--goal-timeout", "nan"], ["--goal-timeout", "finite"]),
        (["--goal-timeout", "0"], ["--goal-timeout", "positive"]),
        (["--fps", "inf"], ["--fps", "finite"]),
        (["--standoff", "-1"], ["--standoff", ">= 0"]),
        (["--video", "ros:/camera/image_raw"], ["--video ros:/camera/image_raw", "--rosbridge"]),
        (["--video", "ros:"], ["names no topic"]),
        (
            ["--video", "ros:/cam", "--rosbridge", "ws://127.0.0.1:9"],
            ["camera /cam", "cannot connect to rosbridge at ws://127.0.0.1:9"],
        ),
        (["--camera-compression", "png"], ["--camera-compression", "png"]),
        (
            ["--video", "ros", "--rosbridge", "ws://127.0.0.1:9"],
            ["--video ros", "turtlesim has no camera topic", "--video ros:/camera"],
        ),
    ],
)
def test_vehicle_bad_input(args: list[str], needles: list[str]) -> None:
    assert_one_line_error(autopilot("vehicle", *args), *needles)


def test_vehicle_unreadable_video_file(tmp_path: Path) -> None:
    junk = tmp_path / "junk.mp4"
    junk.write_text("not a video")
    assert_one_line_error(
        autopilot("vehicle", "--video", str(junk)), "cannot open video file", str(junk)
    )


ROBOT_FILE = """
[velocity]
topic = "/cmd_vel"
type = "geometry_msgs/TwistStamped"

[pose]
topic = "/odom"
type = "nav_msgs/Odometry"

[limits]
max_linear = 0.5
max_angular = 1.0
linear_accel = 1.0
angular_accel = 2.0
"""


@pytest.mark.parametrize(
    ("change", "needles"),
    [
        (("max_angular = 1.0", "max_angular = -1.0"), ["limits.max_angular", ">= 0", "-1.0"]),
        (("[pose]", "wheels = 2\n[pose]"), ["velocity.wheels", "unknown key"]),
        (('"nav_msgs/Odometry"', '"nav_msgs/Odometr"'), ["pose.type", "unknown message type"]),
        (('topic = "/cmd_vel"', ""), ["velocity.topic", "missing"]),
        (("linear_accel = 1.0", 'linear_accel = "quick"'), ["limits.linear_accel", "number"]),
    ],
)
def test_vehicle_bad_robot_file_is_one_line_and_exit_2(
    tmp_path: Path, change: tuple[str, str], needles: list[str]
) -> None:
    # Against a server that is not there: the file is refused before anything starts.
    path = tmp_path / "rover.toml"
    path.write_text(ROBOT_FILE.replace(*change), encoding="utf-8")
    result = autopilot(
        "vehicle",
        "--robot",
        str(path),
        "--rosbridge",
        "ws://127.0.0.1:9",
        "--server",
        "http://127.0.0.1:9",
    )
    assert result.returncode == 2
    assert_one_line_error(result, "--robot", str(path), *needles)


def test_vehicle_robot_that_is_neither_a_preset_nor_a_file() -> None:
    result = autopilot("vehicle", "--robot", "turtlebot4")
    assert result.returncode == 2
    assert_one_line_error(result, "turtlebot4", "turtlesim, diffdrive, turtlebot3")


def test_vehicle_robot_other_than_a_turtlesim_needs_a_rosbridge() -> None:
    result = autopilot("vehicle", "--robot", "turtlebot3")
    assert result.returncode == 2
    assert_one_line_error(result, "--robot turtlebot3", "--rosbridge")


def test_vehicle_refused_login_names_the_reason(server: RunningServer) -> None:
    # A second vehicle with a name already taken in the room: the server's reason is shown.
    with subprocess.Popen(
        [sys.executable, "-m", "vehicle_agent", "--server", server.url, "--name", "v1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    ) as first:
        try:
            assert first.stdout is not None
            for line in first.stdout:
                if "logged in" in line:
                    break
            result = autopilot("vehicle", "--server", server.url, "--name", "v1")
            assert_one_line_error(result, "login refused")
        finally:
            first.terminate()
            first.wait(timeout=20)


def test_relay_unreachable_server() -> None:
    result = autopilot("relay", "--server", "http://127.0.0.1:9")
    assert_one_line_error(result, "cannot reach the server", "127.0.0.1:9")


def test_relay_malformed_server_url() -> None:
    assert_one_line_error(autopilot("relay", "--server", "localhost"), "server URL", "localhost")


def test_demo_port_in_use(server: RunningServer) -> None:
    port = server.url.rsplit(":", 1)[1]
    assert_one_line_error(autopilot("demo", "--port", port), "cannot listen", port)


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["serve", "--port", "70000"], ["--port", "65535"]),
        (["serve", "--port", "0"], ["--port", ">= 1"]),
        (["demo", "--port", "http"], ["--port", "whole number"]),
        (["token", "--room", "lab", "--role", "client", "--ttl", "inf"], ["--ttl", "finite"]),
        (["relay", "--pool", "--max-rooms", "0"], ["--max-rooms", ">= 1"]),
        (["bench", "--soak", "nan"], ["--soak", "finite"]),
        (["bench", "--fps", "-30"], ["--fps", "positive"]),
    ],
)
def test_numbers_out_of_range_are_refused_by_the_parser(
    args: list[str], needles: list[str]
) -> None:
    assert_one_line_error(autopilot(*args), *needles)


def test_a_port_out_of_range_in_the_environment_is_one_line() -> None:
    result = autopilot("serve", env={"AUTOPILOT_PORT": "70000"})
    assert_one_line_error(result, "cannot start", "AUTOPILOT_PORT")
