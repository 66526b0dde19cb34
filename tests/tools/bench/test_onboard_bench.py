"""bench --onboard's figures from an agent's event log and the walker's place
(app/tools/bench/onboard.py), without the stack: a hand-made run."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from app.protocol import events as ev
from app.recording import event_line
from app.tools.bench import onboard


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
