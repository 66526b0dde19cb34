"""Figures and the written report from synthetic runs whose answers are known by construction."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from app.tools.bench import report
from app.tools.bench.results import (
    FIGURE_KEYS,
    POSITION_KEYS,
    MemorySample,
    ProfileRun,
    figures,
    follow_figures,
    results,
)
from app.tools.bench.stats import FaceSample, HeadingSample


def synthetic_run(profile: str, delay_ms: float) -> ProfileRun:
    """30 frames/s for 10 s; every frame becomes a goal 40 ms later and a Twist 10 ms after that;
    the turtle is always 2 degrees off; the heaps grow by 1 % and 2 %; the face leaps across the
    640x480 frame at frame 150 and the goal of frame 151 finds it, the one of 150 does not; the
    client shows each frame 30, 40 or 50 ms after it was captured, in turn."""
    run = ProfileRun(profile)
    run.frame_size = (640, 480)
    for n in range(300):
        t = n / 30
        run.frame_sent[n] = t
        face_x = 100.0 if n < 150 else 500.0
        run.face.append(FaceSample(n, face_x, 200.0))
        run.goal_points[n] = (100.0 if n <= 150 else 500.0, 200.0)
        run.goals.append((t + 0.040, n))
        run.commands.append((t + 0.050, n))
        run.processing.append((t, delay_ms + (n % 2)))  # alternating delay, delay + 1
        run.heading.append(HeadingSample(t, math.radians(32), math.radians(30), math.radians(2)))
        run.client_glass.append(30.0 + 10 * (n % 3))
    run.window = (0.04, 10.04)
    run.settle_at = 1.0
    run.js_ms = [12.0] * 5
    run.native_ms = [10.0] * 5
    run.memory = [MemorySample(0.0, 100.0, 1000.0), MemorySample(10.0, 101.0, 1020.0)]
    return run


def test_figures_of_a_known_run() -> None:
    values, missing = figures(synthetic_run("default", 8.0))
    assert missing == {}
    assert values["processing_ms_p50"] == pytest.approx(8.5)
    assert values["goals_per_s"] == pytest.approx(30.0)
    assert values["glass_to_command_ms_p50"] == pytest.approx(50.0)
    assert values["client_glass_to_glass_ms_p50"] == pytest.approx(40.0)
    assert values["client_glass_to_glass_ms_p95"] == pytest.approx(50.0)
    assert values["heading_error_deg_median"] == pytest.approx(2.0)
    assert values["js_over_native_ratio"] == pytest.approx(1.2)
    assert values["memory_growth_pct"] == pytest.approx(2.0)  # the worse of the two heaps
    assert values["recall_after_jump_pct"] == pytest.approx(100.0)


def test_memory_growth_starts_at_the_baseline() -> None:
    run = synthetic_run("default", 8.0)
    # A buffer filling before the baseline is not growth; what happens after it is.
    run.memory = [
        MemorySample(0.0, 50.0, 1000.0),
        MemorySample(5.0, 100.0, 1000.0),
        MemorySample(10.0, 104.0, 1000.0),
    ]
    run.memory_baseline_at = 4.0
    values, _ = figures(run)
    assert values["memory_growth_pct"] == pytest.approx(4.0)
    run.memory_baseline_at = 11.0  # nothing left to compare with
    values, missing = figures(run)
    assert values["memory_growth_pct"] is None and "memory_growth_pct" in missing


def test_an_empty_run_reports_reasons_not_numbers() -> None:
    run = ProfileRun("thesis")
    run.problems["js_over_native_ratio"] = "the analyzer never loaded"
    values, missing = figures(run)
    assert all(values[key] is None for key in FIGURE_KEYS)
    assert set(missing) == set(FIGURE_KEYS)
    assert missing["js_over_native_ratio"] == "the analyzer never loaded"


def test_write_produces_json_markdown_and_plots(tmp_path: Path) -> None:
    default, thesis = synthetic_run("default", 8.0), ProfileRun("thesis")
    obj = results(default, thesis, {"started": "now", "machine": "test", "fps": 30})
    report.write(tmp_path, obj, default, thesis)

    loaded = json.loads((tmp_path / "results.json").read_text())
    assert loaded["goals_per_s"] == pytest.approx(30.0)
    assert loaded["thesis"]["processing_ms_p50"] is None
    assert "processing_ms_p50" in loaded["unmeasured"]["thesis"]
    for name in report.PLOTS.values():
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = (tmp_path / "report.md").read_text()
    assert "683 ms" in text
    assert "not measured" in text  # the empty thesis run says so instead of showing numbers
    # 8.5 ms p50 against a 15 ms target.
    assert "- **processing p50 <= 15 ms**: 8.5, met." in text


def test_follow_figures_and_report_section(tmp_path: Path) -> None:
    follow = synthetic_run("follow", 8.0)
    # Before the settle time (1 s) the turtle is still driving off: those samples do not count.
    follow.position_error = [(0.5, 5.0)] + [(1.0 + k / 10, 0.1 * (k % 5)) for k in range(50)]
    values, missing = follow_figures(follow)
    assert missing == {}
    assert values["position_error_m_p50"] == pytest.approx(0.2)
    assert values["position_error_m_p95"] == pytest.approx(0.4)
    assert values["goals_per_s"] == pytest.approx(30.0)  # the common figures come along

    default, thesis = synthetic_run("default", 8.0), ProfileRun("thesis")
    obj = results(default, thesis, {"started": "now"}, follow)
    assert obj["follow"]["position_error_m_p50"] == pytest.approx(0.2)
    assert obj["details"]["follow"]["position_error_m"]["n"] == 50
    report.write(tmp_path, obj, default, thesis)
    text = (tmp_path / "report.md").read_text()
    assert "## Follow profile" in text
    assert (
        "p50 0.2 m, p95 0.4 m; **follow: position error p50 <= 0.3 m (face moving)**: met." in text
    )

    empty_values, empty_missing = follow_figures(ProfileRun("follow"))
    assert all(empty_values[key] is None for key in POSITION_KEYS)
    assert set(POSITION_KEYS) <= set(empty_missing)
