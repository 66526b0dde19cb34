"""An optional JSON-lines log of what the agent did and when, for benchmarks and tests.

Each line is one object with ``ev`` and ``t`` (``time.monotonic()`` seconds, comparable across
processes of one machine):

* ``{"ev": "frame_sent", "frame", "face_x", "face_y", "jump", "t"}`` -- synthetic frame handed
  to the encoder, with the true face centre in pixels; ``jump`` is true on the first frame after
  the face leapt across the frame (``SweepPath.jump_times``);
* ``{"ev": "goal", "seq", "op", "frame", "x", "y", "w", "h", "t"}`` -- goal received and applied;
* ``{"ev": "goal_dropped", "seq", "frame", "why", "t"}`` -- goal refused by the latest-wins
  rule (``why``: ``old`` seq or ``stale``) or ignored while the operator drives (``manual``);
* ``{"ev": "mode", "mode", "operator", "t"}`` -- the operator took the wheel or handed it back;
* ``{"ev": "drive", "seq", "applied", "moving", "t"}`` -- an operator's drive command;
* ``{"ev": "twist", "seq", "frame", "linear", "angular", "t"}`` -- Twist published
  (``seq``/``frame`` of the goal that caused it, null for a stop);
* ``{"ev": "pose", "x", "y", "theta", "t"}`` -- pose sent as telemetry;
* ``{"ev": "link", "state", "relay", "t"}`` -- connection to the relay offered, up (with
  ``local_candidates``: the candidate types gathered, and ``selected``: this side's candidate
  type in the nominated pair, or null) or down (with ``reason``);
* ``{"ev": "spawn", "ok", "t", ...}`` -- the spawn step turned the turtle (``x``, ``y``,
  ``theta``) or failed (``reason``);
* ``{"ev": "recorder", "images", "messages", "dropped", "files", "frames", "frames_held",
  "cpu_s", "loop_cpu_s", "writer_cpu_s", "seconds", "t"}`` -- the flight recorder's totals when
  it stopped (``FlightRecorder.totals``), its own CPU time included.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

Event = dict[str, Any]


class EventLog:
    """Writes events to a file (when given) and hands them to in-process listeners."""

    def __init__(self, path: Path | None = None) -> None:
        self._file: IO[str] | None = path.open("a", buffering=1) if path else None
        self.listeners: list[Callable[[Event], None]] = []

    def emit(self, ev: str, **fields: Any) -> None:
        """Record one event, stamped now."""
        event: Event = {"ev": ev, **fields, "t": time.monotonic()}
        if self._file is not None:
            self._file.write(json.dumps(event) + "\n")
        for listener in self.listeners:
            listener(event)

    def close(self) -> None:
        """Flush and close the file."""
        if self._file is not None:
            self._file.close()
            self._file = None
