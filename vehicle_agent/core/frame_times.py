"""When the vehicle's own camera took its recent frames, by frame tag.

A goal names the frame the relay found its target in; a camera the vehicle carries had the
heading of that moment, so the onboard law takes the goal's bearing from the heading then. The
pilot (:meth:`vehicle_agent.core.pilot.Pilot.frame`) keeps one of these, fed with the video source's
:class:`~app.protocol.events.FrameSent` times on its own clock. The browser's twin is
``app/static/js/core/frame-times.js``; both run the pilot's shared sequences
(tests/vehicle_agent/core/pilot_sequences.py), and
tests/vehicle_agent/core/test_frame_times.py states the rule.
"""

from __future__ import annotations

from collections import OrderedDict

from app.protocol.control import KEPT_FRAMES


class FrameTimes:
    """The capture times of the last :data:`~app.protocol.control.KEPT_FRAMES` frames."""

    def __init__(self, kept: int = KEPT_FRAMES) -> None:
        self.kept = kept
        self._times: OrderedDict[int, float] = OrderedDict()

    def add(self, frame: int, at: float) -> None:
        """Frame number ``frame`` was taken at ``at``."""
        self._times[frame] = at
        self._times.move_to_end(frame)
        if len(self._times) > self.kept:
            self._times.popitem(last=False)

    def captured_at(self, frame: int | None) -> float | None:
        """When frame ``frame`` was taken, None when it is not one of the last frames."""
        return None if frame is None else self._times.get(frame)
