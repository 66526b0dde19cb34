"""The recording formats: the agent's event log (JSON lines) and its flight recording (MCAP).

Both hold the event records of :mod:`app.protocol.events`. The event log writes every kind, one
line each (:func:`event_line`, read back by :func:`read_event_log`). The flight recorder
(``vehicle_agent/recorder.py``) writes the kinds of :data:`EVENT_CHANNELS` on their topics and
the camera on :data:`IMAGE_TOPIC`, each channel with a JSON Schema that Foxglove and Lichtblick
read natively; an event's schema is derived from its dataclass (:func:`json_schema`) and its
message is its record without ``ev`` (the topic names the kind), but for a Twist's speeds, which
are a ``geometry_msgs/Twist``'s vectors (:data:`TWIST_SCHEMA`), so that a plot reads
``/turtle1/cmd_vel.angular.z`` as it would a ROS robot's. ``autopilot replay``
(``app/tools/replay.py``) reads the files back here (:func:`messages`, :func:`events`,
:func:`images`, :func:`summary`), without the recorder's media stack.

A file is read as damaged files must be (docs/recording.md): record by record from its start,
each length checked against what is left, each chunk's expansion bounded and its checksum
checked, so that whatever a file says it cannot make the reader hold more than a fixed multiple
of its size; anything wrong is a :class:`RecordingError` naming the file, the byte offset and the
channel. A file cut off (:class:`CutOff`) reads up to its cut.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import json
import struct
import types
import typing
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Literal

import zstandard
from mcap.data_stream import ReadDataStream
from mcap.exceptions import EndOfFile, McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema

from app.protocol import events as ev
from app.protocol.events import AnyEvent, Event
from app.protocol.robot import twist


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
    ev.SearchStarted: EventChannel("/autopilot/search", "autopilot.Search"),
    ev.SearchEnded: EventChannel("/autopilot/search_ended", "autopilot.SearchEnded"),
    ev.LinkChanged: EventChannel("/autopilot/link", "autopilot.Link"),
}
_KIND_OF_TOPIC: Final = {channel.topic: kind for kind, channel in EVENT_CHANNELS.items()}
_VECTOR3: Final[dict[str, Any]] = {
    "type": "object",
    "properties": {axis: {"type": "number"} for axis in "xyz"},
}
# A Twist's speeds in a recorded message: geometry_msgs/Twist's vectors, in the robot's frame.
TWIST_SCHEMA: Final[dict[str, Any]] = {
    "linear": {**_VECTOR3, "description": "m/s: x ahead"},
    "angular": {**_VECTOR3, "description": "rad/s: z counter-clockwise"},
}
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
    if cls is ev.TwistSent:
        properties |= TWIST_SCHEMA
    return {"title": title, "type": "object", "properties": properties}


def channels() -> list[tuple[str, dict[str, Any]]]:
    """Every channel a flight recording has: its topic and JSON Schema (its title the schema's
    name), the camera's first."""
    image = {"title": IMAGE_SCHEMA, "type": "object", "properties": _IMAGE_PROPERTIES}
    recorded = [(c.topic, json_schema(kind, c.schema)) for kind, c in EVENT_CHANNELS.items()]
    return [(IMAGE_TOPIC, image), *recorded]


def message(event: Event) -> dict[str, Any]:
    """``event``'s recorded message: its record without ``ev``, a Twist's speeds as vectors."""
    fields = ev.record(event)
    del fields["ev"]
    if isinstance(event, ev.TwistSent):
        fields |= twist(event.linear, event.angular)
    return fields


def _event_data(kind: type[Event], found: _Recorded) -> str | bytes:
    """A recorded message's event fields as JSON: a Twist's speeds are its ``linear.x`` and
    ``angular.z`` (a recording from before the vectors has the speeds themselves)."""
    fields = found.fields()  # JSON that is not an object is named as such
    if kind is not ev.TwistSent:
        return found.data
    for name, axis in (("linear", "x"), ("angular", "z")):
        vector = fields.get(name)
        if isinstance(vector, dict):
            fields[name] = vector.get(axis)
    return json.dumps(fields)


class RecordingError(ValueError):
    """A flight recording that cannot be read, in one line: the file, the byte offset (of the
    record, or of the chunk a message is in) and the channel where there is one."""


class CutOff(RecordingError):
    """A file that ends before its records do: a run that stopped without finishing it, or a
    disk that filled. What comes before the cut is whole and reads."""


# Bounds on what a file may make the reader hold, whatever it says of itself: a chunk expands
# at most this many times its compressed size, and never beyond the chunk limit. The recorder's
# chunks with images expand a few times, a still turtle's poses alone far more (their numbers
# repeat), a zstd bomb of zeros more again by orders of magnitude.
EXPANSION_LIMIT: Final = 1000
CHUNK_LIMIT: Final = 64 * 2**20
_MAGIC: Final = b"\x89MCAP0\r\n"
_RECORD_HEAD: Final = struct.Struct("<BQ")
# A JPEG starts with its start-of-image marker and the first marker's prefix.
_JPEG_START: Final = b"\xff\xd8\xff"


@dataclass(frozen=True)
class _Recorded:
    """One message as the file holds it: where, on which channel, when, and its bytes."""

    path: Path
    offset: int
    topic: str
    schema: str
    encoding: str
    log_time: int
    data: bytes

    def where(self) -> str:
        return f"{self.path}: the message on {self.topic} at byte {self.offset}"

    def fields(self) -> dict[str, Any]:
        try:
            found = json.loads(self.data)
        except (ValueError, RecursionError) as exc:
            raise RecordingError(f"{self.where()} is not JSON ({_one_line(exc)})") from exc
        if not isinstance(found, dict):
            raise RecordingError(f"{self.where()} is not a JSON object")
        return found


def messages(
    paths: Sequence[Path], on_cut_off: Callable[[CutOff], None] | None = None
) -> Iterator[tuple[str, int, dict[str, Any]]]:
    """Every JSON message of the files, in the order written: (topic, log time ns, fields); the
    Foxglove view's protobuf ones (``vehicle_agent/foxglove.py``) are only counted by
    :func:`summary`. :class:`RecordingError` on a damaged file; a file cut off (:class:`CutOff`)
    goes to ``on_cut_off`` after its whole records, or is raised without it."""
    for found in _scan(paths, on_cut_off):
        if found.encoding == "json":
            yield found.topic, found.log_time, found.fields()


def events(
    paths: Sequence[Path], on_cut_off: Callable[[CutOff], None] | None = None
) -> Iterator[tuple[int, AnyEvent]]:
    """Every recorded event of the files, typed, with its log time (ns), in the order written;
    :class:`RecordingError` on a message that is not its topic's kind (and as
    :func:`messages`)."""
    for found in _scan(paths, on_cut_off):
        kind = _KIND_OF_TOPIC.get(found.topic)
        if kind is not None:
            data = _event_data(kind, found)
            try:
                event = ev.from_fields(kind, data)
            except ev.EventError as exc:
                raise RecordingError(f"{found.where()}: {_one_line(exc)}") from exc
            yield found.log_time, event


def images(
    paths: Sequence[Path], on_cut_off: Callable[[CutOff], None] | None = None
) -> Iterator[tuple[int | None, bytes]]:
    """Every camera image of the files, in the order written: its frame tag (None: untagged)
    and its JPEG bytes; :class:`RecordingError` on an image that is not a tagged JPEG (and as
    :func:`messages`)."""
    for found in _scan(paths, on_cut_off):
        if found.topic != IMAGE_TOPIC:
            continue
        fields = found.fields()
        frame, data = fields.get("frame"), fields.get("data")
        if frame is not None and (not isinstance(frame, int) or isinstance(frame, bool)):
            raise RecordingError(f"{found.where()} has a frame tag that is not an integer")
        if fields.get("format") != "jpeg" or not isinstance(data, str):
            raise RecordingError(f"{found.where()} is not a JPEG image")
        try:
            jpeg = base64.b64decode(data, validate=True)
        except ValueError as exc:
            raise RecordingError(f"{found.where()} has data that is not base64") from exc
        if not jpeg.startswith(_JPEG_START):
            raise RecordingError(f"{found.where()} has data that is not a JPEG")
        yield frame, jpeg


def summary(
    paths: Sequence[Path], on_cut_off: Callable[[CutOff], None] | None = None
) -> dict[str, Any]:
    """Channels (topic, schema, messages), duration and size of the files, from their messages
    (a file cut off has no summary section, and a damaged one may say anything in it)."""
    found_channels: dict[str, dict[str, Any]] = {}
    start, end = None, None
    for found in _scan(paths, on_cut_off):
        entry = found_channels.setdefault(found.topic, {"schema": found.schema, "messages": 0})
        entry["messages"] += 1
        start = found.log_time if start is None else min(start, found.log_time)
        end = found.log_time if end is None else max(end, found.log_time)
    duration = 0.0 if start is None or end is None else (end - start) / 1e9
    return {
        "files": len(paths),
        "bytes": sum(path.stat().st_size for path in paths),
        "duration_s": round(duration, 3),
        "channels": found_channels,
    }


def _scan(
    paths: Sequence[Path], on_cut_off: Callable[[CutOff], None] | None
) -> Iterator[_Recorded]:
    for path in paths:
        try:
            yield from _scan_file(path)
        except CutOff as cut:
            if on_cut_off is None:
                raise
            on_cut_off(cut)
        except OSError as exc:
            raise RecordingError(f"{path}: {exc.strerror or exc}") from exc


def _scan_file(path: Path) -> Iterator[_Recorded]:
    """The messages of one file's data section, read record by record (not through its
    summary section or indexes, which a cut-off file lacks), every length checked against what
    remains and every chunk's expansion bounded."""
    schemas: dict[int, str] = {0: ""}
    channels: dict[int, tuple[str, int, str]] = {}
    for offset, opcode, body in _records(path):
        where = f"{path}: the {_opcode_name(opcode)} record at byte {offset}"
        try:
            if opcode == Opcode.CHUNK:
                chunk = Chunk.read(_Exact(body))
                inner = _records_of(_chunk_data(chunk, where), f"{where}, in its data")
                for _, inner_opcode, inner_body in inner:
                    found = _read(inner_opcode, inner_body, schemas, channels)
                    if found is not None:
                        yield _recorded(path, offset, found, schemas, channels)
            else:
                found = _read(opcode, body, schemas, channels)
                if found is not None:
                    yield _recorded(path, offset, found, schemas, channels)
        except (McapError, struct.error, UnicodeDecodeError) as exc:
            raise RecordingError(f"{where} is damaged ({_one_line(exc) or 'too short'})") from exc
        except _Unknown as exc:
            raise RecordingError(f"{where} {exc}") from exc


class _Unknown(Exception):
    """A message on a channel the file never defined (or a channel on an unknown schema)."""


def _read(
    opcode: int, body: bytes, schemas: dict[int, str], channels: dict[int, tuple[str, int, str]]
) -> Message | None:
    """A message record read; a schema or channel record noted; any other record skipped."""
    if opcode == Opcode.SCHEMA:
        schema = Schema.read(_Exact(body))
        schemas[schema.id] = schema.name
    elif opcode == Opcode.CHANNEL:
        channel = Channel.read(_Exact(body))
        channels[channel.id] = (channel.topic, channel.schema_id, channel.message_encoding)
    elif opcode == Opcode.MESSAGE:
        found: Message = Message.read(_Exact(body), len(body))
        return found
    return None


def _recorded(
    path: Path,
    offset: int,
    found: Message,
    schemas: dict[int, str],
    channels: dict[int, tuple[str, int, str]],
) -> _Recorded:
    if found.channel_id not in channels:
        raise _Unknown(f"has a message on channel {found.channel_id}, which is not defined")
    topic, schema_id, encoding = channels[found.channel_id]
    if schema_id not in schemas:
        raise _Unknown(f"has a message on {topic}, whose schema {schema_id} is not defined")
    schema = schemas[schema_id]
    return _Recorded(path, offset, topic, schema, encoding, found.log_time, found.data)


def _records(path: Path) -> Iterator[tuple[int, int, bytes]]:
    """(offset, opcode, body) of each record of the file's data section. A record that runs
    past the end is a cut (:class:`CutOff`) in a file that was never finished, and damage in
    one that was (it ends with the magic)."""
    size = path.stat().st_size
    with path.open("rb") as stream:
        magic = stream.read(len(_MAGIC))
        if magic != _MAGIC:
            what = "empty" if not magic else f"not an MCAP file (it starts {magic!r})"
            raise RecordingError(f"{path} is {what}")
        stream.seek(max(size - len(_MAGIC), len(_MAGIC)))
        overrun = RecordingError if stream.read() == _MAGIC else CutOff
        stream.seek(len(_MAGIC))
        offset = len(_MAGIC)
        while True:
            head = stream.read(_RECORD_HEAD.size)
            if len(head) < _RECORD_HEAD.size:
                raise overrun(f"{path} is cut off at byte {offset}: the rest is missing")
            opcode, length = _RECORD_HEAD.unpack(head)
            remaining = size - offset - _RECORD_HEAD.size
            if length > remaining:
                problem = "is cut off" if overrun is CutOff else "is damaged"
                raise overrun(
                    f"{path} {problem} at byte {offset}: its {_opcode_name(opcode)} record "
                    f"says {length} bytes, {remaining} remain"
                )
            yield offset, opcode, stream.read(length)
            if opcode in (Opcode.DATA_END, Opcode.FOOTER):
                return  # the summary section after it says nothing the messages do not
            offset += _RECORD_HEAD.size + length


def _records_of(data: bytes, where: str) -> Iterator[tuple[int, int, bytes]]:
    """(offset, opcode, body) of each record of a chunk's data."""
    offset = 0
    while offset < len(data):
        if len(data) - offset < _RECORD_HEAD.size:
            raise RecordingError(f"{where}: a record cut off at byte {offset}")
        opcode, length = _RECORD_HEAD.unpack_from(data, offset)
        start = offset + _RECORD_HEAD.size
        if length > len(data) - start:
            raise RecordingError(f"{where}: a record at byte {offset} longer than the chunk")
        yield offset, opcode, data[start : start + length]
        offset = start + length


def _chunk_data(chunk: Chunk, where: str) -> bytes:
    """A chunk's records, decompressed no further than it may expand and checked."""
    limit = min(CHUNK_LIMIT, EXPANSION_LIMIT * max(len(chunk.data), 1))
    if chunk.uncompressed_size > limit:
        raise RecordingError(
            f"{where} says it holds {chunk.uncompressed_size} bytes in {len(chunk.data)}: more "
            f"than a recording's chunk may ({limit})"
        )
    if chunk.compression == "zstd":
        try:
            # Read no further than the size the chunk says: a frame that holds more is refused
            # below, without ever being held whole.
            data = _decompress(chunk.data, chunk.uncompressed_size + 1)
        except zstandard.ZstdError as exc:
            raise RecordingError(f"{where} does not decompress ({_one_line(exc)})") from exc
    elif chunk.compression == "":
        data = chunk.data
    else:
        raise RecordingError(f"{where} is compressed with {chunk.compression!r}, not zstd")
    if len(data) != chunk.uncompressed_size:
        raise RecordingError(
            f"{where} says it holds {chunk.uncompressed_size} bytes, not the "
            f"{'more' if len(data) > chunk.uncompressed_size else len(data)} it does"
        )
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise RecordingError(f"{where} is damaged (its checksum does not match)")
    return data


def _decompress(data: bytes, most: int) -> bytes:
    """At most ``most`` bytes of zstd ``data``, whatever its frame header says."""
    parts, wanted = [], most
    with zstandard.ZstdDecompressor().stream_reader(data) as reader:
        while wanted > 0:
            part = reader.read(wanted)
            if not part:
                break
            parts.append(part)
            wanted -= len(part)
    return b"".join(parts)


class _Exact(ReadDataStream):
    """A record's body: reading past its end is an error, not a short read."""

    def __init__(self, body: bytes) -> None:
        super().__init__(io.BytesIO(body))

    def read(self, length: int) -> bytes:
        data = super().read(length)
        if len(data) != length:
            raise EndOfFile(f"{length} bytes wanted, {len(data)} left")
        return data


def _opcode_name(opcode: int) -> str:
    try:
        return Opcode(opcode).name.lower().replace("_", " ")
    except ValueError:
        return f"unknown (opcode {opcode:#x})"


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


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
