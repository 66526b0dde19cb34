"""The agent remembers when its camera took its recent frames (vehicle_agent/frame_times.py)."""

from __future__ import annotations

from app.protocol.events import FrameSent, GoalDropped
from vehicle_agent.frame_times import FrameTimes


def test_a_frames_capture_time_is_kept_for_the_last_120_frames() -> None:
    times = FrameTimes()
    for frame in range(1, 201):
        times.on_event(FrameSent(frame=frame, face_x=320.0, face_y=240.0, t=frame / 30))
    times.on_event(GoalDropped(seq=1, frame=300, why="old", t=9.0))  # not a frame
    assert times.captured_at(200) == 200 / 30
    assert times.captured_at(81) == 81 / 30
    assert times.captured_at(80) is None  # 121 frames ago: forgotten
    assert times.captured_at(300) is None and times.captured_at(None) is None
