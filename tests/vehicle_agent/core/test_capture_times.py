"""The capture times' batches: every 0.1 s or when full, each frame once, numbered as the tag."""

from __future__ import annotations

from app.protocol import channels
from app.protocol.channels import AUTOPILOT_STATE_CHANNEL, FrameTimes
from vehicle_agent.core.capture_times import CaptureTimes


def feed(times: CaptureTimes, frames: range, fps: float = 30.0) -> list[FrameTimes]:
    """Frames captured at ``fps`` from t = 0; the batches they made."""
    batches = []
    for frame in frames:
        t = frame / fps
        batch = times.add(frame, 1.7e12 + t * 1000, t)
        if batch is not None:
            batches.append(batch)
    return batches


def test_a_batch_goes_out_0_1_s_after_its_first_frame_with_every_frame_once() -> None:
    batches = feed(CaptureTimes(), range(31))
    # At 30 frames/s: frames 0..3 (the fourth comes 0.1 s after the first), 4..7, ...
    assert [[f.frame for f in b.frames] for b in batches[:2]] == [[0, 1, 2, 3], [4, 5, 6, 7]]
    sent = [f.frame for b in batches for f in b.frames]
    assert sent == list(range(len(sent))) and len(sent) >= 28
    assert batches[0].frames[1].t == 1.7e12 + 1000 / 30


def test_a_full_batch_goes_out_at_once() -> None:
    # A camera faster than the period: 64 frames is the most one message holds.
    batches = feed(CaptureTimes(), range(200), fps=10_000.0)
    assert [len(b.frames) for b in batches] == [channels.MAX_FRAME_TIMES] * 3


def test_frame_numbers_wrap_as_the_tag_does() -> None:
    times = CaptureTimes(period_s=0.0)
    batch = times.add((1 << 24) + 5, 1.0, 0.0)
    assert batch is not None and batch.frames[0].frame == 5


def test_a_batch_is_a_message_the_relay_accepts() -> None:
    (batch, *_) = feed(CaptureTimes(), range(10))
    parsed = channels.parse(channels.dump(batch), AUTOPILOT_STATE_CHANNEL, "relay")
    assert parsed == batch
