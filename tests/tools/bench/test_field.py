"""The field bench's figures from an agent event log (keys and plausibility; no timings)."""

from __future__ import annotations

from pathlib import Path

from app.protocol import events as ev
from app.tools.bench.field import (
    figures,
    link_drop_times,
    samples_since,
    stale_goals_applied,
    write,
)


def _log() -> list[ev.AnyEvent]:
    """A link that comes up, then 40 frames at 20/s, each turned into a goal and a Twist 60 ms
    later, with the turtle facing the face (160, 240 px: straight left of the centre)."""
    events: list[ev.AnyEvent] = [
        ev.LinkChanged(state="offer", relay="relay", t=0.0),
        ev.LinkChanged(state="up", relay="relay", selected="relay", t=0.25),
    ]
    for i in range(40):
        t = 1.0 + i * 0.05
        events.append(ev.FrameSent(frame=i, face_x=160, face_y=240, t=t))
        events.append(_goal(i + 1, i, t + 0.04))
        events.append(ev.TwistSent(seq=i + 1, frame=i, linear=0.0, angular=1.0, t=t + 0.06))
        events.append(ev.PoseReport(x=5.544445, y=5.544445, theta=3.14159, sent=True, t=t + 0.07))
    return events


def _goal(seq: int, frame: int | None, t: float) -> ev.GoalApplied:
    return ev.GoalApplied(seq=seq, op="face", frame=frame, x=160, y=240, w=640, h=480, t=t)


def test_figures_have_every_key_and_plausible_values() -> None:
    row = figures("turn_only", _log(), (1.0, 3.0))
    assert row.candidate_type == "relay"
    assert row.connect_ms == 250.0
    assert row.glass_to_command_ms_p50 == 60.0 and row.glass_to_command_ms_p95 == 60.0
    assert 19 <= (row.goals_per_s or 0) <= 20
    assert row.heading_error_deg_median is not None and row.heading_error_deg_median < 1
    assert row.stale_goals_applied == 0
    assert row.problems == {}


def test_the_client_glass_to_glass_over_the_window() -> None:
    # The ring holds the latest samples; those taken since the first reading are the window's.
    before = {"count": 10, "ms": [90.0] * 10}
    after = {"count": 14, "ms": [90.0] * 10 + [40.0, 50.0, 60.0, 70.0]}
    row = figures("rtt_150", _log(), (1.0, 3.0))
    row.client_glass(samples_since(before, after))
    assert (row.client_glass_to_glass_ms_p50, row.client_glass_to_glass_ms_p95) == (55.0, 68.5)
    empty = figures("loss_2", _log(), (1.0, 3.0))
    empty.client_glass(samples_since(after, after))
    assert "client_glass_to_glass_ms_p50" in empty.problems


def test_a_goal_applied_after_a_newer_one_counts_as_stale_until_the_next_link() -> None:
    events = _log()
    events.append(_goal(12, 11, 4.0))  # older than seq 40
    events.append(ev.LinkChanged(state="up", relay="relay", t=5.0))
    events.append(_goal(1, 50, 5.1))  # a new link counts again
    assert stale_goals_applied(events) == 1


def test_link_drop_times_from_the_last_goal_and_from_the_link_coming_back() -> None:
    events: list[ev.AnyEvent] = [
        _goal(1, None, 10.0),
        ev.TwistSent(seq=None, frame=None, linear=0.0, angular=0.0, t=10.8),
        _goal(2, None, 13.6),
    ]
    assert link_drop_times(events, dark_at=10.2, back_at=13.2) == {
        "stop_after_s": 0.8,
        "resume_after_s": 0.4,
    }


def test_a_run_without_a_link_says_why(tmp_path: Path) -> None:
    row = figures("clean", [], (0.0, 1.0))
    assert "connect_ms" in row.problems and "glass_to_command_ms_p50" in row.problems
    obj = {"field": [row.__dict__], "link_drop": {"stop_after_s": None, "resume_after_s": None}}
    video = {
        "condition": "cap_300kbit",
        "hint": "motion",
        "degradation_preference": "maintain-framerate",
        "fps": 9.5,
        "width": 320,
        "kbit_per_s": 220,
        "limited_by": "bandwidth",
    }
    run = {"started": "2026-11-26T18:00:00+00:00", "machine": "2 x CPU", "command": "bench"}
    write(tmp_path, {**obj, "window_s": 1.0, "quick": True, "video": [video], "run": run})
    report = (tmp_path / "field.md").read_text()
    assert "Run 2026-11-26T18:00:00+00:00 on 2 x CPU, command `bench`." in report
    # No link_drop row: no outage figures, not even as "not measured".
    assert "link_drop:" not in report
    dropped = figures("link_drop", [], (0.0, 1.0)).__dict__
    write(tmp_path, {**obj, "field": [dropped], "window_s": 1.0, "quick": True, "video": []})
    assert "link_drop: zero Twist – s after the last goal" in (tmp_path / "field.md").read_text()
    assert "clean connect_ms: the link never came up" in report
    assert "| cap_300kbit | motion | maintain-framerate | 9.5 | 320 | 220 | bandwidth |" in report
    assert (tmp_path / "field-latency.png").stat().st_size > 0
