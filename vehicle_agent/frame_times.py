"""When the vehicle's own camera took its recent frames, by frame tag.

A goal names the frame the relay found its target in; a camera the vehicle carries had the
heading of that moment, so the onboard law takes the goal's bearing from the heading then
(:meth:`vehicle_agent.pilot.Pilot.goal`'s ``captured_at``). The times come from the video
source's :class:`~app.protocol.events.FrameSent` events, on the agent's clock.
"""

from __future__ import annotations

from collections import OrderedDict

from app.protocol.events import AnyEvent, FrameSent

# Frames remembered: more than a second of a 30 fps camera, and goals older than that are
# stale anyway.
KEPT_FRAMES = 120


class FrameTimes:
    """The capture times of the last :data:`KEPT_FRAMES` frames; an event log listener."""

    def __init__(self) -> None:
        self._times: OrderedDict[int, float] = OrderedDict()

    def on_event(self, event: AnyEvent) -> None:
        """Remember a frame's capture time (other events are not this one's)."""
        if isinstance(event, FrameSent):
            self._times[event.frame] = event.t
            self._times.move_to_end(event.frame)
            if len(self._times) > KEPT_FRAMES:
                self._times.popitem(last=False)

    def captured_at(self, frame: int | None) -> float | None:
        """When frame ``frame`` was taken, None when it is not one of the last frames."""
        return None if frame is None else self._times.get(frame)
