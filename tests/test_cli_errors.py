"""Bad input on the command line: one line naming the problem, non-zero exit, no traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from app.server.serve import RunningServer


def autopilot(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
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
        (["--rosbridge", "ws://127.0.0.1:9"], ["rosbridge", "ws://127.0.0.1:9"]),
        (["--rosbridge", "robot:9090"], ["rosbridge URL", "robot:9090"]),
        (["--size", "big"], ["size", "big"]),
        (["--size", "641x480"], ["size", "641x480"]),
        (["--profile", "fastest"], ["fastest"]),
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
