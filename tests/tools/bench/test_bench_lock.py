"""``lock_held_pct`` from a run's goals on the two-face scene, and its place in the report."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.tools.bench import lock, report
from app.tools.bench.results import ProfileRun, results
from vehicle_agent.video import TwoFaceVideo

SCENE = TwoFaceVideo()


def run_with_goals(on_small: int, on_large: int) -> ProfileRun:
    run = ProfileRun("default", window=(0.0, 30.0))
    for frame in range(on_small + on_large):
        centre = SCENE.small_centre(frame) if frame < on_small else SCENE.face_centre(frame)
        run.goals.append((frame / SCENE.fps, frame))
        # A detected box's centre is a few pixels off the true one.
        run.goal_points[frame] = (centre[0] + 3, centre[1] - 2)
    run.goals.append((40.0, 5))  # after the window: not counted
    run.goals.append((1.0, None))  # untagged: not counted
    return run


def test_share_of_goals_on_the_smaller_face_and_the_report(tmp_path: Path) -> None:
    found = lock.figures(run_with_goals(on_small=57, on_large=3), SCENE)
    assert found["value"] == pytest.approx(95.0)
    assert found["details"]["on_smaller"] == 57 and found["details"]["on_larger"] == 3

    default, thesis = ProfileRun("default"), ProfileRun("thesis")
    obj = results(default, thesis, {"started": "now"})
    lock.merge(obj, run_with_goals(on_small=20, on_large=0), SCENE)
    assert obj["lock_held_pct"] == 100.0 and obj["unmeasured"]["lock"] == {}
    report.write(tmp_path, obj, default, thesis)
    text = (tmp_path / "report.md").read_text()
    assert "## Target lock" in text and "20 of 20" in text
    assert "**lock held on the smaller face >= 95 % of goals (two faces)**: met." in text


def test_a_run_that_could_not_lock_says_why() -> None:
    failed = ProfileRun(
        "default", problems={lock.KEY: "a click on the smaller face did not lock it"}
    )
    found = lock.figures(failed, SCENE)
    assert found["value"] is None and "did not lock" in found["reason"]
    assert lock.figures(ProfileRun("default", window=(0.0, 1.0)), SCENE)["reason"]
