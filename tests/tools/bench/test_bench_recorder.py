"""``autopilot bench --recorder`` as a user runs it: both runs measured (the agent's cores, its
latencies), the CPU increase computed, the report and a real recording written. Timings are the
report's business, never asserted here."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from app.tools.bench import recording as recording_bench

pytestmark = [
    pytest.mark.bench,
    pytest.mark.slow,
    pytest.mark.browser,
    pytest.mark.timeout(400),
    pytest.mark.xdist_group("benches"),  # the shorter benches' lane (test_field_quick.py)
]


def test_the_recorder_bench_measures_both_runs_and_writes_its_report(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "app.cli", "bench", "--recorder", "--json"]
    argv += ["--seconds", "4", "--fps", "10", "--out", str(tmp_path)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=360)
    assert done.returncode == 0, done.stderr[-3000:]
    figures = json.loads(done.stdout.splitlines()[-1])
    assert figures["problems"] == {}
    for name in ("plain", "recording"):
        run = figures[name]
        assert 0 < run["agent_cores"] < 2, run
        for key in ("glass_to_command_ms", "goal_to_command_ms"):
            assert 0 <= run[key]["p50"] <= run[key]["p95"] < 5000, run
    recording = figures["recording"]
    assert recording["mcap_bytes"] > 0
    assert isinstance(figures["agent_cpu_increase_pct"], float)
    # Alternating rounds (plain, recording, plain, recording), each with its own increase.
    assert len(figures["rounds"]) == recording_bench.ROUNDS >= 2, figures["rounds"]
    for found in figures["rounds"]:
        assert 0 < found["plain_cores"] < 2 and 0 < found["recording_cores"] < 2, found
        assert isinstance(found["increase_pct"], float)
    # The recorder's own CPU, from the agent's event log: some, the writer's part of it.
    assert 0 < recording["recorder_writer_cores"] <= recording["recorder_cores"] < 1, recording
    assert 0 < recording["recorder_share_pct"] < 100 and recording["recorder_images"] > 0
    assert 0 < recording["recorder_frames_held_pct"] <= 100
    report = (tmp_path / "recorder.md").read_text()
    assert "| recording |" in report and "Agent CPU with recording" in report
    assert "round by round" in report
    assert "The recorder's own CPU" in report
    assert json.loads((tmp_path / "recorder.json").read_text()) == figures
