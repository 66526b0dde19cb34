"""The pilot remembers when its camera took its recent frames
(vehicle_agent/core/frame_times.py)."""

from __future__ import annotations

from vehicle_agent.core.frame_times import FrameTimes


def test_a_frames_capture_time_is_kept_for_the_last_120_frames() -> None:
    times = FrameTimes()
    for frame in range(1, 201):
        times.add(frame, frame / 30)
    assert times.captured_at(200) == 200 / 30
    assert times.captured_at(81) == 81 / 30
    assert times.captured_at(80) is None  # 121 frames ago: forgotten
    assert times.captured_at(300) is None and times.captured_at(None) is None


def test_a_frame_taken_again_counts_as_the_newest() -> None:
    times = FrameTimes(kept=2)
    times.add(1, 0.1)
    times.add(2, 0.2)
    times.add(1, 0.3)  # the tag wrapped round to 1 again
    times.add(3, 0.4)
    assert times.captured_at(1) == 0.3 and times.captured_at(2) is None
