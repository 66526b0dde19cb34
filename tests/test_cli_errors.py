"""Bad input on the command line: one line naming the problem, non-zero exit, no traceback.

The many bad inputs that are refused before anything starts (the parser, the URLs, the video
source, the robot file) run ``autopilot``'s ``main`` in this process; a few of each command's
run as a whole process, for the wiring: the exit status and the one line a user sees.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from app.cli import main
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


def in_process(
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture, *args: str
) -> tuple[int, str]:
    """Exit status and the one error line of ``autopilot args`` run in this process: the
    parser's ``error:`` line or the one record logged at ERROR (no other error, no traceback)."""
    caplog.clear()
    try:
        status = main(list(args))
    except SystemExit as exited:  # the parser's refusal
        status = exited.code if isinstance(exited.code, int) else 1
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err, out + err
    errors = [line for line in (out + err).splitlines() if "error:" in line]
    for record in caplog.records:
        if record.levelno >= logging.ERROR:
            assert record.exc_info is None, record
            errors += record.getMessage().splitlines() or [""]
    assert status != 0 and len(errors) == 1, (status, out + err, caplog.records)
    return status, errors[0]


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
        (["--server", "not-a-url"], ["server URL", "not-a-url"]),
        (["--video", "/no/such/clip.mp4"], ["no such video file", "/no/such/clip.mp4"]),
        (["--video", "/dev/video99"], ["no such video device", "/dev/video99"]),
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
        (["--camera-compression", "png"], ["--camera-compression", "png"]),
        (
            ["--video", "ros", "--rosbridge", "ws://127.0.0.1:9"],
            ["--video ros", "turtlesim has no camera topic", "--video ros:/camera"],
        ),
    ],
)
def test_vehicle_bad_input(
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
    args: list[str],
    needles: list[str],
) -> None:
    _, line = in_process(capsys, caplog, "vehicle", *args)
    for needle in needles:
        assert needle in line, line


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--server", "http://127.0.0.1:9"], ["signaling server", "127.0.0.1:9"]),
        (["--rosbridge", "ws://127.0.0.1:9"], ["rosbridge", "ws://127.0.0.1:9", "refused"]),
        (
            ["--video", "ros:/cam", "--rosbridge", "ws://127.0.0.1:9"],
            ["camera /cam", "cannot connect to rosbridge at ws://127.0.0.1:9"],
        ),
    ],
)
def test_vehicle_unreachable_peers_are_one_line_from_the_process(
    args: list[str], needles: list[str]
) -> None:
    # Whole processes: what connecting fails on reaches the user as one line and a status.
    result = autopilot("vehicle", *args)
    assert result.returncode == 1
    assert_one_line_error(result, *needles)


def test_vehicle_unreadable_video_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    junk = tmp_path / "junk.mp4"
    junk.write_text("not a video")
    _, line = in_process(capsys, caplog, "vehicle", "--video", str(junk))
    assert "cannot open video file" in line and str(junk) in line, line


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
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
    change: tuple[str, str],
    needles: list[str],
) -> None:
    # Against a server that is not there: the file is refused before anything starts.
    path = tmp_path / "rover.toml"
    path.write_text(ROBOT_FILE.replace(*change), encoding="utf-8")
    args = [
        "--robot",
        str(path),
        "--rosbridge",
        "ws://127.0.0.1:9",
        "--server",
        "http://127.0.0.1:9",
    ]
    status, line = in_process(capsys, caplog, "vehicle", *args)
    assert status == 2
    for needle in ("--robot", str(path), *needles):
        assert needle in line, line


def test_a_bad_robot_file_is_one_line_and_exit_2_from_the_process(tmp_path: Path) -> None:
    path = tmp_path / "rover.toml"
    path.write_text(ROBOT_FILE.replace("max_angular = 1.0", "max_angular = -1.0"), "utf-8")
    result = autopilot("vehicle", "--robot", str(path), "--rosbridge", "ws://127.0.0.1:9")
    assert result.returncode == 2
    assert_one_line_error(result, "--robot", str(path), "limits.max_angular")


@pytest.mark.parametrize(
    ("robot", "needles"),
    [
        ("turtlebot4", ["turtlebot4", "turtlesim, diffdrive, turtlebot3"]),
        # Not a parse error, the same status: a turtlesim is the only in-process simulator.
        ("turtlebot3", ["--robot turtlebot3", "--rosbridge"]),
    ],
)
def test_vehicle_robot_that_cannot_be_driven_as_given(
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
    robot: str,
    needles: list[str],
) -> None:
    status, line = in_process(capsys, caplog, "vehicle", "--robot", robot)
    assert status == 2
    for needle in needles:
        assert needle in line, line


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


def test_relay_malformed_server_url(
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    _, line = in_process(capsys, caplog, "relay", "--server", "localhost")
    assert "server URL" in line and "localhost" in line, line


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
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
    args: list[str],
    needles: list[str],
) -> None:
    status, line = in_process(capsys, caplog, *args)
    assert status == 2  # argparse's
    for needle in needles:
        assert needle in line, line


def test_a_port_out_of_range_in_the_environment_is_one_line() -> None:
    result = autopilot("serve", env={"AUTOPILOT_PORT": "70000"})
    assert_one_line_error(result, "cannot start", "AUTOPILOT_PORT")
