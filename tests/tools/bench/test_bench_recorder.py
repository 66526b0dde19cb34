"""``autopilot bench --recorder``: the recorder's share and the CPU increase checked against a
hand-made run, the report's rows; then the command as a user runs it, on one short round (both
runs measured, the report and a real recording written). Timings are the report's business,
never asserted here."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from app.protocol.events import RecorderTotals, record
from app.tools.bench import recording as recording_bench


def totals(cpu_s: float, writer_cpu_s: float, seconds: float, frames: int, held: int) -> str:
    """One ``recorder`` event's log line (5 images, the rest of its fields alike)."""
    found = RecorderTotals(
        t=1.0,
        images=5,
        messages=10,
        dropped=0,
        files=1,
        frames=frames,
        frames_held=held,
        cpu_s=cpu_s,
        loop_cpu_s=cpu_s - writer_cpu_s,
        writer_cpu_s=writer_cpu_s,
        seconds=seconds,
    )
    return json.dumps(record(found)) + "\n"


def test_the_recorder_s_share_sums_every_recording_run(tmp_path: Path) -> None:
    # Two runs: 0.3 + 0.1 CPU-s over 2 + 2 s = 0.1 cores, 0.2 of it the writer's (0.05);
    # 10 of 40 frames held; the agent at 0.4 cores: the recorder's 25 %.
    first, second = tmp_path / "events-1.jsonl", tmp_path / "events-2.jsonl"
    first.write_text(totals(0.3, 0.15, 2.0, 20, 4))
    second.write_text(totals(0.1, 0.05, 2.0, 20, 6))
    assert recording_bench._recorder_share([first, second], 0.4) == {
        "recorder_cores": 0.1,
        "recorder_writer_cores": 0.05,
        "recorder_images": 10,
        "recorder_frames_held_pct": 25,
        "recorder_share_pct": 25.0,
    }
    # Without the agent's cores, no share; without a recorder event, nothing.
    assert "recorder_share_pct" not in recording_bench._recorder_share([first], None)
    (tmp_path / "plain.jsonl").write_text("")
    assert recording_bench._recorder_share([tmp_path / "plain.jsonl"], 0.4) == {}


def test_the_increase_is_the_recording_runs_cores_over_the_plain_ones() -> None:
    assert recording_bench._increase_pct(0.40, 0.42) == 5.0
    assert recording_bench._increase_pct(0.50, 0.45) == -10.0


def test_the_report_holds_both_modes_each_round_and_the_recorder_s_cpu(tmp_path: Path) -> None:
    figures = {
        "seconds": 4.0,
        "fps": 10.0,
        "round_count": 2,
        "rounds": [
            {"plain_cores": 0.4, "recording_cores": 0.42, "increase_pct": 5.0},
            {"plain_cores": 0.5, "recording_cores": 0.45, "increase_pct": -10.0},
        ],
        "problems": {},
        "plain": {
            "agent_cores": 0.45,
            "glass_to_command_ms": {"p50": 80.0, "p95": 120.0},
            "goal_to_command_ms": {"p50": 2.0, "p95": 4.0},
        },
        "recording": {
            "agent_cores": 0.435,
            "glass_to_command_ms": {"p50": 81.0, "p95": 125.0},
            "goal_to_command_ms": None,
            "mcap_bytes": 2_500_000,
            "recorder_cores": 0.1,
            "recorder_writer_cores": 0.05,
            "recorder_images": 10,
            "recorder_frames_held_pct": 25,
            "recorder_share_pct": 23.0,
        },
        "agent_cpu_increase_pct": -3.3,
    }
    report = recording_bench.write_report(tmp_path, figures).read_text()
    assert "4 s of each in 2 alternating rounds" in report
    assert "| plain | 0.45 | 80.0 / 120.0 | 2.0 / 4.0 |" in report
    assert "| recording | 0.435 | 81.0 / 125.0 | – |" in report
    assert "Agent CPU with recording: -3.3 % (target ≤ +5 %)" in report
    assert "0.4 → 0.42 (+5.0 %), 0.5 → 0.45 (-10.0 %)" in report
    assert "0.1 cores, 23.0 % of the recording agent's (writer thread 0.05; 10 images" in report
    assert "Recorded: 2.5 MB" in report
    assert json.loads((tmp_path / "recorder.json").read_text()) == figures


@pytest.mark.bench
@pytest.mark.slow
@pytest.mark.browser
@pytest.mark.timeout(200)
@pytest.mark.xdist_group("benches")  # the shorter benches' lane (test_field_quick.py)
def test_the_recorder_bench_measures_both_runs_and_writes_its_report(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "app.cli", "bench", "--recorder", "--json", "--rounds", "1"]
    argv += ["--seconds", "1", "--fps", "10", "--out", str(tmp_path)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=180)
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
    # One round, as asked: its increase is the whole run's.
    assert figures["round_count"] == 1
    (found,) = figures["rounds"]
    assert found["plain_cores"] == figures["plain"]["agent_cores"]
    assert found["recording_cores"] == figures["recording"]["agent_cores"]
    # The whole run's increase comes from each mode's mean cores, the round's from its own: with
    # one round they are the same numbers (both from unrounded cores).
    assert figures["agent_cpu_increase_pct"] == found["increase_pct"]
    # The recorder's own CPU, from the agent's event log: some, the writer's part of it.
    assert 0 < recording["recorder_writer_cores"] <= recording["recorder_cores"] < 1, recording
    assert 0 < recording["recorder_share_pct"] < 100 and recording["recorder_images"] > 0
    assert 0 < recording["recorder_frames_held_pct"] <= 100
    report = (tmp_path / "recorder.md").read_text()
    assert "| recording |" in report and "in 1 alternating rounds" in report
    assert json.loads((tmp_path / "recorder.json").read_text()) == figures
