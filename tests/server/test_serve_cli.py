"""``autopilot serve`` refuses bad configuration with one line, not a traceback."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest


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
        ({"AUTOPILOT_ENVIRONMENT": "production"}, "AUTOPILOT_TOKEN must be set"),
        ({"AUTOPILOT_MAX_MESSAGE_BYTES": "lots"}, "max_message_bytes"),
        ({"AUTOPILOT_OPERATIONS_SPEC": "/nonexistent/ops.json"}, "/nonexistent/ops.json"),
    ],
)
def test_bad_configuration_is_one_line_and_exit_1(env: dict[str, str], words: str) -> None:
    result = _serve(env)
    assert result.returncode == 1
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert "cannot start" in lines[0] and words in lines[0]


def test_broken_operations_spec_names_the_problem(tmp_path: Path) -> None:
    spec = tmp_path / "ops.json"
    spec.write_text("{not json")
    result = _serve({"AUTOPILOT_OPERATIONS_SPEC": str(spec)})
    assert result.returncode == 1
    assert "not valid JSON" in result.stderr
