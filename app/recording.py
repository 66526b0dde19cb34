"""The recording formats: the agent's event log (JSON lines) and its flight recording (MCAP).

Both hold the event records of :mod:`app.protocol.events`. The event log writes every kind, one
line each (:func:`event_line`, read back by :func:`read_event_log`). The flight recorder
(``vehicle_agent/recorder.py``) writes the kinds of :data:`EVENT_CHANNELS` on their topics and
the camera on :data:`IMAGE_TOPIC`, each channel with a JSON Schema that Foxglove and Lichtblick
read natively; an event's schema is derived from its dataclass (:func:`json_schema`) and its
message is its record without ``ev`` (the topic names the kind). ``autopilot replay``
(``app/tools/replay.py``) reads the files back here (:func:`messages`, :func:`events`,
:func:`summary`), without the recorder's media stack.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal

from mcap.exceptions import McapError
from mcap.reader import make_reader

from app.protocol import events as ev
from app.protocol.events import AnyEvent, Event


@dataclass(frozen=True)
class EventChannel:
    """Where one event kind is recorded: its topic and its schema's name."""

    topic: str
    schema: str


IMAGE_TOPIC: Final = "/camera/image/compressed"
# foxglove.CompressedImage as Foxglove's JSON schema has it, plus the frame tag.
IMAGE_SCHEMA: Final = "foxglove.CompressedImage"
_STAMP: Final = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
}
_IMAGE_PROPERTIES: Final[dict[str, Any]] = {
    "timestamp": _STAMP,
    "frame_id": {"type": "string"},
    "data": {"type": "string", "contentEncoding": "base64"},
    "format": {"type": "string"},
    "frame": {"type": ["integer", "null"], "description": "frame tag (docs/contracts.md)"},
}
# The event kinds the flight recorder keeps, where (the synthetic camera's truth and the
# recorder's own totals are the event log's only).
EVENT_CHANNELS: Final[dict[type[Event], EventChannel]] = {
    ev.PoseReport: EventChannel("/turtle1/pose", "turtlesim.Pose"),
    ev.TwistSent: EventChannel("/turtle1/cmd_vel", "autopilot.Twist"),
    ev.GoalApplied: EventChannel("/autopilot/goal", "autopilot.Goal"),
    ev.GoalDropped: EventChannel("/autopilot/goal_dropped", "autopilot.GoalDropped"),
    ev.ModeChanged: EventChannel("/autopilot/mode", "autopilot.Mode"),
    ev.DriveReceived: EventChannel("/autopilot/drive", "autopilot.Drive"),
    ev.LinkChanged: EventChannel("/autopilot/link", "autopilot.Link"),
}
_KIND_OF_TOPIC: Final = {channel.topic: kind for kind, channel in EVENT_CHANNELS.items()}
_T_DESCRIPTION: Final = "seconds, the vehicle's monotonic clock (the MCAP log time is UTC)"


# --- the event log ------------------------------------------------------------------------------


def event_line(event: Event) -> str:
    """One line of the event log (without its newline)."""
    return json.dumps(ev.record(event))


def read_event_log(path: Path, *, growing: bool = False) -> list[AnyEvent]:
    """The events of a log file, oldest first. ``growing``: the file is still being written,
    so a last line without its newline is left for later rather than refused."""
    text = path.read_text()
    lines = text.splitlines(keepends=True)
    if growing and lines and not lines[-1].endswith("\n"):
        lines.pop()
    return [ev.from_json(line) for line in lines if line.strip()]


# --- the flight recording -----------------------------------------------------------------------


def json_schema(cls: type[Event], title: str) -> dict[str, Any]:
    """The JSON Schema of ``cls``'s recorded message (every field; ``t`` described)."""
    hints = typing.get_type_hints(cls)
    properties = {f.name: _schema_of(hints[f.name]) for f in dataclasses.fields(cls)}
    properties["t"] = {**properties["t"], "description": _T_DESCRIPTION}
    return {"title": title, "type": "object", "properties": properties}


def channels() -> list[tuple[str, dict[str, Any]]]:
    """Every channel a flight recording has: its topic and JSON Schema (its title the schema's
    name), the camera's first."""
    image = {"title": IMAGE_SCHEMA, "type": "object", "properties": _IMAGE_PROPERTIES}
    recorded = [(c.topic, json_schema(kind, c.schema)) for kind, c in EVENT_CHANNELS.items()]
    return [(IMAGE_TOPIC, image), *recorded]


def message(event: Event) -> dict[str, Any]:
    """``event``'s recorded message: its record without ``ev``."""
    fields = ev.record(event)
    del fields["ev"]
    return fields


def messages(paths: Sequence[Path]) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """Every message of the files in log-time order per file: (topic, log time ns, fields)."""
    for path in paths:
        with path.open("rb") as stream:
            for _, channel, found in make_reader(stream).iter_messages(log_time_order=True):
                yield channel.topic, found.log_time, json.loads(found.data)


def events(paths: Sequence[Path]) -> Iterator[tuple[int, AnyEvent]]:
    """Every recorded event of the files, typed, with its log time (ns), in log-time order per
    file; :class:`~app.protocol.events.EventError` on a message that is not its topic's kind."""
    for path in paths:
        with path.open("rb") as stream:
            for _, channel, found in make_reader(stream).iter_messages(log_time_order=True):
                kind = _KIND_OF_TOPIC.get(channel.topic)
                if kind is not None:
                    yield found.log_time, ev.from_fields(kind, found.data)


def summary(paths: Sequence[Path]) -> dict[str, Any]:
    """Channels (topic, schema, messages), duration and size of the files, from their
    summary sections."""
    found_channels: dict[str, dict[str, Any]] = {}
    start, end, size = None, None, 0
    for path in paths:
        size += path.stat().st_size
        with path.open("rb") as stream:
            found = make_reader(stream).get_summary()
        if found is None or found.statistics is None:
            raise McapError(f"{path} has no summary (a recording cut off before it was finished)")
        stats = found.statistics
        for channel_id, channel in found.channels.items():
            entry = found_channels.setdefault(
                channel.topic,
                {"schema": found.schemas[channel.schema_id].name, "messages": 0},
            )
            entry["messages"] += stats.channel_message_counts.get(channel_id, 0)
        if stats.message_count:
            start = min(start or stats.message_start_time, stats.message_start_time)
            end = max(end or stats.message_end_time, stats.message_end_time)
    duration = 0.0 if start is None or end is None else (end - start) / 1e9
    return {
        "files": len(paths),
        "bytes": size,
        "duration_s": round(duration, 3),
        "channels": found_channels,
    }


_JSON_TYPES: Final[dict[type, str]] = {
    bool: "boolean",
    int: "integer",
    float: "number",
    str: "string",
}


def _schema_of(hint: Any) -> dict[str, Any]:
    """A field's JSON Schema from its type: the scalars, Literal, ``tuple[X, ...]`` and
    ``X | None``."""
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        members = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(members) != 1:
            raise TypeError(f"no JSON Schema for {hint!r}")
        inner = _schema_of(members[0])
        nullable = {**inner, "type": [inner["type"], "null"]}
        if "enum" in inner:
            nullable["enum"] = [*inner["enum"], None]
        return nullable
    if origin is Literal:
        values = typing.get_args(hint)
        return {"type": _JSON_TYPES[type(values[0])], "enum": list(values)}
    if origin is tuple:
        item, rest = typing.get_args(hint)
        if rest is not Ellipsis:
            raise TypeError(f"no JSON Schema for {hint!r}")
        return {"type": "array", "items": _schema_of(item)}
    if hint in _JSON_TYPES:
        return {"type": _JSON_TYPES[hint]}
    raise TypeError(f"no JSON Schema for {hint!r}")
