"""An optional JSON-lines log of what the agent did and when, for benchmarks and tests.

The events are the typed records of :mod:`app.protocol.events` (one frozen dataclass per kind);
each line is :func:`app.recording.event_line` (``ev``, the fields, ``t``), read back by
:func:`app.recording.read_event_log`. In-process listeners (the flight recorder, the metrics,
tests) get the event objects themselves.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import IO

from app.protocol.events import AnyEvent
from app.recording import event_line

Listener = Callable[[AnyEvent], None]


class EventLog:
    """Writes events to a file (when given) and hands them to in-process listeners."""

    def __init__(self, path: Path | None = None) -> None:
        self._file: IO[str] | None = path.open("a", buffering=1) if path else None
        self.listeners: list[Listener] = []

    def emit(self, event: AnyEvent) -> None:
        """Record one event."""
        if self._file is not None:
            self._file.write(event_line(event) + "\n")
        for listener in self.listeners:
            listener(event)

    def close(self) -> None:
        """Flush and close the file."""
        if self._file is not None:
            self._file.close()
            self._file = None
