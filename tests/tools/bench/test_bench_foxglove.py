"""``autopilot bench --foxglove`` as a user runs it: every phase measured in every round (goal →
Twist, the listeners' time with a goal's record, the loop's CPU in the Foxglove view), images
encoded only while a viewer asks for them, the change against the same round's no-viewer phase,
the load and the date in the report. Timings are the report's business, never asserted here."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from app.tools.bench.foxglove import NO_VIEWER, PHASES, QUICK_ROUNDS, STUCK, VIEWER

pytestmark = [pytest.mark.bench, pytest.mark.slow]


def test_the_foxglove_bench_measures_every_phase_in_rounds_and_writes_its_report(
    tmp_path: Path,
) -> None:
    argv = [sys.executable, "-m", "app.cli", "bench", "--foxglove", "--quick", "--json"]
    argv += ["--seconds", "3", "--fps", "15", "--out", str(tmp_path)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    figures = json.loads(done.stdout.splitlines()[-1])
    assert figures["rounds"] == QUICK_ROUNDS and len(figures["load"]) == 6
    for phase in PHASES:
        found = figures[phase]
        assert len(found["p50_rounds"]) == QUICK_ROUNDS
        pooled = found["pooled"]
        assert pooled["n"] > 0 and 0 < pooled["p50"] <= pooled["p95"], found
        assert found["listeners_p50"] >= 0 and found["loop_ms_per_s"] > 0
    # Only the viewers ask for the camera: nothing is encoded without one.
    assert figures[NO_VIEWER]["images"] == 0
    assert figures[VIEWER]["images"] > 0 and figures[STUCK]["images"] > 0
    for phase in (VIEWER, STUCK):
        assert isinstance(figures[phase]["p50_change_pct"], float)
    report = (tmp_path / "foxglove.md").read_text()
    assert "| stuck viewer |" in report and "against the same round's no viewer" in report
    assert figures["date"] in report
    assert json.loads((tmp_path / "foxglove.json").read_text()) == figures
