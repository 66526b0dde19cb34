"""``autopilot replay``'s agreement rule, its exit status against ``--min-agreement`` and its
answers to bad input (the real replay of a recorded demo run is in test_demo.py)."""

from __future__ import annotations

import base64
import contextlib
import json
from pathlib import Path
from typing import Any

import cv2
import pytest
from mcap.writer import Writer

from app.cli import main
from app.protocol.events import GoalApplied
from app.recording import EVENT_CHANNELS, IMAGE_TOPIC, message
from app.tools import replay
from app.tools.replay import AGREE_FRACTION, Recording, compare
from tests.helpers.harness import open_harness
from vehicle_agent.video import FixedPath, SyntheticVideo


def _goal(frame: int, x: float, y: float = 240.0, op: str = "face") -> GoalApplied:
    return GoalApplied(seq=frame, op=op, frame=frame, x=x, y=y, w=640, h=480, t=frame / 30)


def test_goals_are_compared_on_recorded_frames_and_agree_within_the_tolerance() -> None:
    near = AGREE_FRACTION * 640 * 0.9
    recording = Recording(
        images={1: b"one", 3: b"three", 4: b"four", 9: b"nine"},
        goals={1: _goal(1, 100), 2: _goal(2, 100), 3: _goal(3, 100), 4: _goal(4, 300)},
        images_recorded=4,
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


def _write_recording(
    path: Path, goals: dict[int, tuple[float, float]], undecodable: frozenset[int] = frozenset()
) -> None:
    """An MCAP file as the recorder writes it: for each frame tag, the camera's image of that
    frame (a face at a fixed place) and the goal the relay sent for it, at (x, y); the frames
    of ``undecodable`` have an image that starts as a JPEG does and is not one."""
    video = SyntheticVideo(path=FixedPath(0.3, 0.42))
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema(name="any", encoding="jsonschema", data=b"{}")
        images, goal_topic = (
            writer.register_channel(topic, message_encoding="json", schema_id=schema)
            for topic in (IMAGE_TOPIC, EVENT_CHANNELS[GoalApplied].topic)
        )
        for frame, (x, y) in goals.items():
            bgr = cv2.cvtColor(video.render(frame), cv2.COLOR_RGB2BGR)
            data = cv2.imencode(".jpg", bgr)[1].tobytes()
            if frame in undecodable:
                data = data[:3] + bytes(64)
            jpeg = base64.b64encode(data).decode()
            image = {"format": "jpeg", "data": jpeg, "frame": frame}
            goal = message(_goal(frame, x, y))
            for channel, fields in ((images, image), (goal_topic, goal)):
                data = json.dumps(fields).encode()
                writer.add_message(channel, log_time=frame, data=data, publish_time=frame)
        writer.finish()  # type: ignore[no-untyped-call]


@pytest.mark.browser
@pytest.mark.slow
def test_replay_exits_1_below_the_minimum_agreement_and_0_at_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    # Two recorded goals: one on the face the replay finds, one far from it: 50 % agree.
    face = SyntheticVideo(path=FixedPath(0.3, 0.42)).face_centre(0)
    recording = tmp_path / "run.mcap"
    _write_recording(recording, {1: face, 2: (face[0] + 300, face[1])})
    with open_harness() as harness:
        # Both runs analyse in the one real harness (a launch costs seconds).
        monkeypatch.setattr(replay, "open_harness", lambda: contextlib.nullcontext(harness))
        statuses = []
        for minimum in ("50.01", "50"):
            statuses.append(main(["replay", "--min-agreement", minimum, "--json", str(recording)]))
            last = json.loads(capsys.readouterr().out.splitlines()[-1])
            assert (last["goals_compared"], last["agreed"]) == (2, 1), last
        assert statuses == [1, 0]
        # An image the browser cannot decode, though it starts as a JPEG: one line naming it.
        broken = tmp_path / "broken.mcap"
        _write_recording(broken, {1: face, 2: face}, undecodable=frozenset({2}))
        assert main(["replay", str(broken)]) == 2
        [line] = capsys.readouterr().err.splitlines()
        assert line.startswith("autopilot replay: cannot read the recording: the image of frame 2 ")
        assert "the browser cannot decode it" in line, line
