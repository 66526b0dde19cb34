"""``autopilot replay``'s agreement rule and its answers to bad input (the real replay of a
recorded demo run is in test_demo.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from app.cli import main
from app.protocol.events import GoalApplied
from app.tools.replay import AGREE_FRACTION, Recording, compare


def _goal(frame: int, x: float, op: str = "face") -> GoalApplied:
    return GoalApplied(seq=frame, op=op, frame=frame, x=x, y=240.0, w=640, h=480, t=frame / 30)


def test_goals_are_compared_on_recorded_frames_and_agree_within_the_tolerance() -> None:
    near = AGREE_FRACTION * 640 * 0.9
    recording = Recording(
        images={1: b"one", 3: b"three", 4: b"four", 9: b"nine"},
        goals={1: _goal(1, 100), 2: _goal(2, 100), 3: _goal(3, 100), 4: _goal(4, 300)},
    )
    replayed: dict[bytes, dict[str, Any]] = {
        b"one": {"x": 100 + near, "y": 240},
        b"three": {"x": 400, "y": 240},
    }
    seen: list[str] = []

    def analyse(jpeg: bytes, op: str) -> dict[str, Any] | None:
        seen.append(op)
        return replayed.get(jpeg)

    result = compare(recording, analyse)
    # Frame 2 has no image; frame 9 has no goal: neither is compared.
    assert (result.frames, result.goals_recorded, result.goals_compared) == (4, 4, 3)
    assert (result.goals_replayed, result.agreed) == (2, 1)
    assert result.agreement_pct == pytest.approx(100 / 3)
    assert [d["frame"] for d in result.disagreements] == [3, 4]
    assert result.disagreements[1]["replayed"] is None
    assert seen == ["face"] * 3
    compare(recording, analyse, op="fire")
    assert seen[3:] == ["fire"] * 3


def test_an_unreadable_recording_is_one_line_and_exit_status_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bogus = tmp_path / "not.mcap"
    bogus.write_bytes(b"this is not an MCAP file")
    for options in ([], ["--summary"]):
        assert main(["replay", *options, str(bogus)]) == 2
        assert "cannot read the recording" in capsys.readouterr().err
    assert main(["replay", str(tmp_path / "missing.mcap")]) == 2
    assert "cannot read the recording" in capsys.readouterr().err
