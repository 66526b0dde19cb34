"""``autopilot serve`` refuses bad configuration with one line, not a traceback."""

from __future__ import annotations

import asyncio
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import websockets

from tests.test_cli_errors import in_process


def _serve(env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", "serve", "--port", "1"],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=60,
    )


@pytest.mark.parametrize(
    ("env", "words"),
    [
        ({"AUTOPILOT_ENVIRONMENT": "production"}, "AUTOPILOT_SECRET must be set"),
        ({"AUTOPILOT_TOKEN": "old-shared-token"}, "AUTOPILOT_TOKEN is no longer used"),
        ({"AUTOPILOT_SECRET": "short"}, "at least 16 characters"),
        ({"AUTOPILOT_ALLOWED_ORIGINS": '["evil"]'}, "an origin looks like"),
        ({"AUTOPILOT_MAX_MESSAGE_BYTES": "lots"}, "AUTOPILOT_MAX_MESSAGE_BYTES must be an integer"),
        ({"AUTOPILOT_PORT": "abc"}, "AUTOPILOT_PORT must be an integer"),
        ({"AUTOPILOT_OPERATIONS_SPEC": "/nonexistent/ops.json"}, "/nonexistent/ops.json"),
        ({"AUTOPILOT_ROS": "3"}, "AUTOPILOT_ROS: Input should be"),
    ],
)
def test_bad_configuration_is_one_line_and_exit_1(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
    env: dict[str, str],
    words: str,
) -> None:
    # In this process: a bad setting is refused before anything starts.
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    status, line = in_process(capsys, caplog, "serve", "--port", "1")
    assert status == 1
    assert "cannot start" in line and words in line, line


def test_a_bad_setting_is_one_line_and_exit_1_from_the_process() -> None:
    result = _serve({"AUTOPILOT_ENVIRONMENT": "production"})
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert "cannot start" in lines[0] and "AUTOPILOT_SECRET must be set" in lines[0]


def test_broken_operations_spec_names_the_problem(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    spec = tmp_path / "ops.json"
    spec.write_text("{not json")
    monkeypatch.setenv("AUTOPILOT_OPERATIONS_SPEC", str(spec))
    status, line = in_process(capsys, caplog, "serve", "--port", "1")
    assert status == 1 and "not valid JSON" in line, line


def test_ros_flavour_outside_the_choices_is_refused(
    capsys: pytest.CaptureFixture[str], caplog: pytest.LogCaptureFixture
) -> None:
    status, line = in_process(capsys, caplog, "serve", "--ros", "4")
    assert status == 2 and "'1', '2', 'jazzy'" in line, line


async def test_serve_ros_1_speaks_ros_1_type_names() -> None:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--port", str(port), "--ros", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        call = {
            "op": "call_service",
            "service": "/rosapi/topic_type",
            "args": {"topic": "/turtle1/pose"},
        }
        async with asyncio.timeout(30):
            while True:
                try:
                    ws = await websockets.connect(f"ws://127.0.0.1:{port}/rosbridge")
                    break
                except OSError:
                    await asyncio.sleep(0.1)
            async with ws:
                await ws.send(json.dumps(call))
                reply = json.loads(await ws.recv())
        assert reply["values"] == {"type": "turtlesim/Pose"}
    finally:
        server.terminate()
        server.wait(timeout=10)
