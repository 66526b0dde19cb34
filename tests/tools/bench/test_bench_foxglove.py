"""``autopilot bench --foxglove`` as a user runs it: both phases measured (goal → Twist, the loop's
CPU in the Foxglove view), the stuck viewer's images encoded, the report written. Timings are the
report's business, never asserted here."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.bench, pytest.mark.slow]


def test_the_foxglove_bench_measures_both_phases_and_writes_its_report(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "app.cli", "bench", "--foxglove", "--json"]
    argv += ["--seconds", "4", "--fps", "15", "--out", str(tmp_path)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    figures = json.loads(done.stdout.splitlines()[-1])
    for phase in ("plain", "stuck viewer"):
        found = figures[phase]
        assert found["n"] > 0 and 0 < found["p50"] <= found["p95"], found
        assert figures[f"{phase} loop_ms_per_s"] > 0
    # Only the stuck viewer asks for the camera: its images were encoded.
    assert figures["images"] > 0
    assert isinstance(figures["p50_increase_pct"], float)
    report = (tmp_path / "foxglove.md").read_text()
    assert "| stuck viewer |" in report and "p50 with the stuck viewer" in report
    assert json.loads((tmp_path / "foxglove.json").read_text()) == figures
