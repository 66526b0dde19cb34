"""bench --onboard's figures from an agent's event log and the walker's place
(app/tools/bench/onboard.py), without the stack: a hand-made run."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from app.protocol import events as ev
from app.recording import event_line
from app.resources import OPERATIONS_SPEC
from app.tools.bench import onboard
from app.vision.spec import load_spec


def test_the_figures_of_a_hand_made_run(tmp_path: Path) -> None:
    # The robot stands at (1, 3) facing east for 6 s, a pose every 0.1 s. The walker stands 1.5 m
    # ahead, goes behind the robot's left at 2 s and is back ahead, 2° off, at 4.5 s.
    def walker(t: float) -> tuple[float, float] | None:
        if t < 2.0:
            return (2.5, 3.0)
        if t < 4.5:
            return (0.0, 4.0)  # behind, to the left: bearing 135°
        return (2.5, 3.0 + 1.5 * math.tan(math.radians(2.0)))

    log = [
        *[ev.PoseReport(x=1.0, y=3.0, theta=0.0, sent=True, t=k / 10) for k in range(61)],
        # Frames taken 0.05 s before the Twist their goal made: 50 ms each.
        *[ev.FrameSent(frame=k, face_x=320.0, face_y=240.0, t=k / 10) for k in range(1, 20)],
        *[
            ev.TwistSent(seq=k, frame=k, linear=0.0, angular=0.1, t=k / 10 + 0.05)
            for k in range(1, 20)
        ],
        ev.SearchStarted(side="left", t=2.3),
        ev.SearchEnded(why="found", after_s=2.2, t=4.5),
    ]
    path = tmp_path / "events.jsonl"
    path.write_text("".join(event_line(e) + "\n" for e in log))
    found = onboard.figures(path, (0.0, 6.0), walker, math.radians(60))

    assert found["problems"] == {}
    # In view: 0° for 2 s (20 poses), then 2° for 1.5 s (16 poses).
    assert found["bearing_err_deg_p50"] == pytest.approx(0.0, abs=0.01)
    assert found["bearing_err_deg_p95"] == pytest.approx(2.0, abs=0.01)
    assert found["standoff_err_m_p50"] == pytest.approx(0.3, abs=0.01)  # 1.5 m, standoff 1.2
    # Nearest while behind the robot, out of view: from (1, 3) to (0, 4).
    assert found["min_distance_m"] == pytest.approx(math.sqrt(2), abs=1e-3)
    # Out of view at 2.0, back within 5° at 4.5.
    assert found["reacquire_s"] == pytest.approx(2.5, abs=1e-6)
    assert found["reacquisitions"] == [{"left_at_s": 2.0, "side": "left", "after_s": 2.5}]
    assert found["frame_to_twist_ms_p50"] == pytest.approx(50.0, abs=0.1)
    assert found["searches"] == [[2.3, "searching left"], [4.5, "search found"]]


def test_a_departure_the_run_ended_on_counts_only_when_it_outlasted_the_longest(
    tmp_path: Path,
) -> None:
    # Out of view from 1.0 to 3.0 (back after 2 s), and again from 4.5 to the end at 5.0:
    # at least 0.5 s, shorter than 2 s, so the longest is 2 s.
    def walker(t: float) -> tuple[float, float]:
        return (1.0, 1.0) if 1.0 <= t < 3.0 or t >= 4.5 else (2.5, 3.0)

    log = [ev.PoseReport(x=1.0, y=3.0, theta=0.0, sent=True, t=k / 10) for k in range(51)]
    path = tmp_path / "events.jsonl"
    path.write_text("".join(event_line(e) + "\n" for e in log))
    found = onboard.figures(path, (0.0, 5.0), walker, math.radians(60))
    assert found["reacquire_s"] == pytest.approx(2.0)
    assert [r["after_s"] for r in found["reacquisitions"]] == [pytest.approx(2.0), None]


def test_a_walker_never_back_leaves_reacquire_missing_with_the_reason(tmp_path: Path) -> None:
    log = [ev.PoseReport(x=1.0, y=3.0, theta=0.0, sent=True, t=k / 10) for k in range(31)]
    path = tmp_path / "events.jsonl"
    path.write_text("".join(event_line(e) + "\n" for e in log))
    found = onboard.figures(
        path, (0.0, 3.0), lambda t: (2.5, 3.0) if t < 1.0 else (1.0, 1.0), math.radians(60)
    )
    assert "reacquire_s" not in found
    assert found["problems"]["reacquire_s"] == (
        "the walker left the view by the right at 1.0 s and was not back within 5° in the 2.0 s"
        " before the run ended"
    )
    assert "no Twist" in found["problems"]["frame_to_twist_ms_p50"]


def test_the_report_sets_the_operations_side_by_side_against_the_targets(tmp_path: Path) -> None:
    # Two hand-made walks: the targets are goals/s >= 28, bearing p50 <= 2° and p95 <= 10°,
    # standoff p50 within ±0.10 m, never nearer than 0.6 m, reacquire <= 4 s, and no click
    # after the first lock.
    met = {
        "bearing_err_deg_p50": 1.5,
        "bearing_err_deg_p95": 9.0,
        "standoff_err_m_p50": -0.08,
        "min_distance_m": 0.65,
        "reacquire_s": 3.5,
        "clicks_after_first": 0,
        "goals_per_s": 29.0,
    }
    missed = {
        "bearing_err_deg_p50": 2.5,
        "bearing_err_deg_p95": 26.0,
        "standoff_err_m_p50": -0.12,
        "min_distance_m": 0.4,
        "reacquire_s": 14.0,
        "clicks_after_first": 3,
        "goals_per_s": 12.0,
    }
    common = {"seconds": 90.0, "fps": 30.0, "video": "ros:/camera", "problems": {}}
    run_info = {
        "command": "autopilot bench --onboard",
        "machine": "a test",
        "started": "now",
        "load_average": [1.0, 1.0],
    }
    runs = {"face_dnn": common | met, "face_small": common | missed}
    path = onboard.write_report(tmp_path, runs, run_info)
    rows = {
        line.split("|")[1].strip(" `"): [cell.strip() for cell in line.split("|")[2:4]]
        for line in path.read_text().splitlines()
        if line.startswith("| `")
    }
    assert path.read_text().count("| `face_dnn` | `face_small` | target |") == 1
    for key in met:
        assert rows[key][0].endswith("✓") and rows[key][1].endswith("✗"), (key, rows[key])
    assert rows["clicks_after_first"] == ["0 ✓", "3 ✗"]
    saved = json.loads((tmp_path / "onboard.json").read_text())
    assert list(saved["operations"]) == ["face_dnn", "face_small"]
    assert saved["operations"]["face_small"]["goals_per_s"] == 12.0


def test_ops_name_operations_the_relay_offers() -> None:
    from app.tools.bench.cli import _onboard_ops

    offered = {op.id for op in load_spec(OPERATIONS_SPEC).operations}
    assert _onboard_ops(None) == [op for op in ("face_small", "face_dnn") if op in offered]
    assert _onboard_ops("face, face_small,face") == ["face", "face_small"]
    with pytest.raises(ValueError, match="nope is not one the relay offers"):
        _onboard_ops("face_small,nope")
    with pytest.raises(ValueError, match="no operation"):
        _onboard_ops(",")
