"""The camera's capture times, batched for the relay: ``frameTimes`` on the state channel.

A client that shows frame n (it reads n from the frame tag) and knows when the vehicle captured
n measures glass to glass: capture at the vehicle to presentation at the client
(docs/contracts.md, "Glass to glass"). The agent feeds each tagged frame it hands to the encoder
into :class:`CaptureTimes`; every :data:`PERIOD_S` the frames gathered since the last batch go
out in one message, which the relay forwards to its clients. Sans-I/O: times are given, never
read, and the agent sends what :meth:`CaptureTimes.add` returns.
"""

from __future__ import annotations

from typing import Final

from app.protocol import frametag
from app.protocol.channels import MAX_FRAME_TIMES, FrameTime, FrameTimes

# A batch every this many seconds: a few frames a message at 30 frames/s. A client matches a
# frame it showed with its capture time whichever arrives first, so the batching delays only
# when the figure is known, not the figure itself.
PERIOD_S: Final = 0.1


class CaptureTimes:
    """Frames captured since the last batch, and when the next batch is due."""

    def __init__(self, period_s: float = PERIOD_S) -> None:
        self.period_s = period_s
        self._pending: list[FrameTime] = []
        self._first_at = 0.0

    def add(self, frame: int, captured_ms: float, now: float) -> FrameTimes | None:
        """Record that frame number ``frame`` was captured at ``captured_ms`` (Unix ms on the
        vehicle's clock); ``now`` is a monotonic clock in seconds. Returns the batch to send when
        one is due: :data:`PERIOD_S` after its first frame, or once it is full."""
        if not self._pending:
            self._first_at = now
        # The frame number as the tag carries it (it wraps).
        self._pending.append(FrameTime(frame=frame % (1 << frametag.LAYOUT.bits), t=captured_ms))
        if now - self._first_at < self.period_s and len(self._pending) < MAX_FRAME_TIMES:
            return None
        batch, self._pending = self._pending, []
        return FrameTimes(frames=batch)
