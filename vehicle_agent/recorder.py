"""The flight recorder: what the vehicle saw, was told and did, in MCAP files Foxglove opens.

``autopilot vehicle --record DIR`` writes ``DIR/autopilot-<room>-<UTC time>.mcap``: the camera as
``foxglove.CompressedImage`` (JPEG, each with its frame tag), and the agent's events on the topics
of :mod:`app.recording` (pose, every Twist sent, every goal received or dropped, mode changes,
drive commands, link events), whose JSON Schemas derive from the events' dataclasses.

Why ``mcap`` with JSON Schema rather than ``foxglove-sdk`` with protobuf: every event is already a
JSON-able record (its event-log line), the schemas read like the wire protocol's, and Foxglove and
Lichtblick read JSON-schema channels natively; zstd chunk compression wins back most of what the
base64 of the images adds.

Which camera images are kept: ``--record-fps`` of them, and by preference the frames the relay
sent goals for (a goal names its frame by tag), so that ``autopilot replay`` can check the goals
against their own images. The loop holds camera frames to pick from (references, their tags read
from the top rows only, and only when a search asks), but only from shortly before an image is
due: from as long before as the last goal took to come back for its frame, plus a margin (from a
second before, after a period that no goal filled). Holding every frame for a second would cost
the loop most of the recorder's share (whoever lets go of a frame last pays for freeing it) and
memory; holding from the lead still finds a slow link's goals. When no goal names a held frame
(autopilot off, a camera without tags) the newest frame is kept a period after it was due, so
the rate holds either way.

Recording never waits on the disk: the agent's loop only stamps an item and queues it; one thread
drains the queue once a second, JPEG-encodes and writes. A full queue drops the item
(counted, logged once) rather than slow the loop. Log times are one clock (``time.time_ns()``,
or the recorder's ``clock``), taken when the event happened. Files roll over by size and age, and
only the newest ``max_files`` are kept, so a day's run cannot fill the disk unnoticed.

A disk that refuses must not stop the vehicle: the first file is opened when the recorder starts,
so that a folder it cannot write is said then (:class:`RecorderError`); a write refused later
(a full disk) is one warning, the file is left as far as it got (its whole chunks read back,
``app/recording.py``), what comes meanwhile is dropped and counted, and each drain tries a new
file until the disk takes one.

The recorder counts its own CPU time, the loop's share and the writer thread's
(:meth:`FlightRecorder.totals`), so that what it costs the agent is measured directly, not only
as the difference between two runs of a noisy machine (``autopilot bench --recorder``).
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import collections
import contextlib
import json
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any, Final, Literal

import av
import cv2
import numpy as np
from aiortc import MediaStreamTrack
from mcap.writer import CompressionType, Writer

from app import recording
from app.arguments import positive_number
from app.protocol import frametag
from app.protocol.events import AnyEvent, GoalApplied, RecorderTotals

log = logging.getLogger(__name__)

# How long camera frames are held at most for a goal to name one (glass-to-goal is tens of
# milliseconds; a loaded relay's, hundreds).
HOLD_NS: Final = 1_000_000_000
# Holding starts this long before the next image is due beyond the last goal's own delay (frame
# arrival to its goal): a frame of a 30 fps camera, for the delay's jitter. A goal that still
# names a frame from before the lead costs only a wait for the next goal.
LEAD_MARGIN_NS: Final = 35_000_000
# Pixel formats whose first plane the tag is read from as it is: the luma (the tag's blocks are
# white and black in it too) or packed RGB; by channels per pixel.
_FIRST_PLANE_CHANNELS: Final = {
    **dict.fromkeys(("yuv420p", "yuvj420p", "yuv422p", "yuv444p", "nv12", "gray"), 1),
    **dict.fromkeys(("rgb24", "bgr24"), 3),
}
# Items waiting for the writer thread (about a hundred a second under the autopilot); beyond
# this the recorder drops rather than queue memory.
QUEUE_LIMIT: Final = 512
# The writer thread drains the queue this often. Not woken per item: a wake-up per event would
# hand the GIL back and forth with the agent's loop dozens of times a second, and larger batches
# cost the thread less per item (JPEG's code and tables stay in the cache). Nothing is lost for
# it: a file is only readable up to its last whole chunk until it is finished.
DRAIN_PERIOD_S: Final = 1.0


@dataclass(frozen=True)
class RecordSettings:
    """How to record: images per second, JPEG quality, when to roll over, how many to keep."""

    folder: Path
    room: str = "default"
    fps: float = 5.0
    jpeg_quality: int = 80
    max_mb: float = 100.0
    max_minutes: float = 60.0
    max_files: int = 20
    # What the writer holds before it writes a chunk: at most what a crash or a full disk loses.
    chunk_bytes: int = 1024 * 1024


@dataclass(frozen=True)
class ExtraChannel:
    """A channel beside the recording's own: its topic, schema and encodings."""

    topic: str
    schema: str
    schema_encoding: str
    schema_data: bytes
    encoding: str


class RecorderError(Exception):
    """The recording's folder cannot be written: said when the recorder starts."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The recording options (``autopilot vehicle``; ``autopilot demo`` passes them on)."""
    defaults = RecordSettings(Path())
    group = parser.add_argument_group("flight recorder")
    group.add_argument(
        "--record",
        type=Path,
        metavar="DIR",
        help="record camera, pose, goals, Twists, mode and link events as MCAP files in DIR",
    )
    group.add_argument(
        "--record-fps",
        type=positive_number,
        default=defaults.fps,
        help=f"camera images recorded per second (default {defaults.fps:g})",
    )
    group.add_argument(
        "--record-quality",
        type=_quality,
        default=defaults.jpeg_quality,
        help=f"JPEG quality of the images, 1-100 (default {defaults.jpeg_quality})",
    )
    group.add_argument(
        "--record-max-mb",
        type=positive_number,
        default=defaults.max_mb,
        help=f"start a new file past this size (default {defaults.max_mb:g} MB)",
    )
    group.add_argument(
        "--record-max-minutes",
        type=positive_number,
        default=defaults.max_minutes,
        help=f"start a new file past this age (default {defaults.max_minutes:g} min)",
    )
    group.add_argument(
        "--record-keep",
        type=int,
        default=defaults.max_files,
        metavar="N",
        help=f"keep only the newest N files, deleting older ones (default {defaults.max_files})",
    )


def settings_from(args: argparse.Namespace, room: str) -> RecordSettings | None:
    """The recording asked for on the command line, or None without ``--record``."""
    if args.record is None:
        return None
    return RecordSettings(
        folder=args.record,
        room=room,
        fps=args.record_fps,
        jpeg_quality=args.record_quality,
        max_mb=args.record_max_mb,
        max_minutes=args.record_max_minutes,
        max_files=max(1, args.record_keep),
    )


def arguments_of(args: argparse.Namespace) -> list[str]:
    """The recording options of ``args`` as a command line, to pass on (none without
    ``--record``)."""
    if args.record is None:
        return []
    return [
        "--record",
        str(args.record.resolve()),
        "--record-fps",
        str(args.record_fps),
        "--record-quality",
        str(args.record_quality),
        "--record-max-mb",
        str(args.record_max_mb),
        "--record-max-minutes",
        str(args.record_max_minutes),
        "--record-keep",
        str(args.record_keep),
    ]


def _quality(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value <= 100:
        raise argparse.ArgumentTypeError(f"JPEG quality must be 1 to 100, not {text!r}")
    return value


class _Held:
    """A camera frame the recorder may still keep: when it arrived, and its tag once read."""

    __slots__ = ("_tag", "arrived_ns", "frame")

    def __init__(self, arrived_ns: int, frame: av.VideoFrame) -> None:
        self.arrived_ns = arrived_ns
        self.frame = frame
        self._tag: int | None | Literal[False] = False  # False: not read yet

    @property
    def tag(self) -> int | None:
        """The frame's tag, read on first use: most held frames are never asked for it (only
        those a due goal's search passes, and the images kept), and reading a fresh frame's top
        rows is the loop's costliest step per frame."""
        if self._tag is False:
            self._tag = frame_tag(self.frame)
        return self._tag


def frame_tag(frame: av.VideoFrame) -> int | None:
    """``frame``'s tag, read from its top rows only (the luma or packed RGB plane as it is, no
    conversion of the whole frame): cheap enough for every frame of the camera."""
    rows = frametag.block_size(frame.width)
    channels = _FIRST_PLANE_CHANNELS.get(frame.format.name)
    if channels is None:
        return frametag.read(np.asarray(frame.to_ndarray(format="gray"), np.uint8))
    plane = frame.planes[0]
    top = np.frombuffer(memoryview(plane), np.uint8, count=rows * plane.line_size)
    pixels = top.reshape(rows, plane.line_size)[:, : frame.width * channels]
    return frametag.read(pixels.reshape(rows, frame.width, channels))


def encode_jpeg(frame: av.VideoFrame, quality: int) -> bytes:
    """``frame`` as a JPEG of ``quality`` (1-100); also the live Foxglove view's."""
    # To BGR, OpenCV's order: libswscale converts a camera's YUV in one step, but swapping
    # packed RGB's channels is faster in OpenCV (the synthetic camera's frames).
    if frame.format.name == "rgb24":
        rgb = frame.to_ndarray(format="rgb24")
        bgr = np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), np.uint8)
    else:
        bgr = np.asarray(frame.to_ndarray(format="bgr24"), np.uint8)
    ok, jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return bytes(jpeg.tobytes())


class FlightRecorder:
    """Records the agent's events (:meth:`on_event`) and camera (:meth:`record_video`)."""

    def __init__(
        self,
        settings: RecordSettings,
        clock: Callable[[], int] = time.time_ns,
        extra: Sequence[ExtraChannel] = (),
    ) -> None:
        """``clock``: wall-clock nanoseconds, the recording's one clock (log times, image
        timestamps, file names and ages). ``extra``: more channels, written by :meth:`record`
        (the Foxglove view's, ``vehicle_agent/foxglove.py``). :class:`RecorderError` when the
        folder cannot be written, found by opening the first file."""
        self.settings = settings
        self._extra = tuple(extra)
        self._clock = clock
        self.files: list[Path] = []
        self.images = 0
        self.messages = 0
        self.dropped = 0
        # CPU seconds: the agent loop's share (thread-time deltas around the recorder's own
        # work) and the writer thread's (its whole thread time).
        self._loop_cpu_s = 0.0
        self._writer_cpu_s = 0.0
        self._started_s = time.monotonic()
        # deque.append and popleft are atomic: the loop appends without a lock or a wake-up.
        self._queue: collections.deque[tuple[str, int, Any]] = collections.deque()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._write_all, name="flight-recorder")
        self._file: IO[bytes] | None = None
        self._writer: Writer | None = None
        self._channels: dict[str, int] = {}
        self._opened_ns = 0
        self._bytes = 0
        # The camera's frames held (record_video), when the next image is due, and how long
        # before that holding starts (module docstring).
        self._held: collections.deque[_Held] = collections.deque()
        self._period_ns = int(1e9 / settings.fps)
        self._due_ns = 0
        self._lead_ns = HOLD_NS
        self._kept_ns = 0  # the last image kept: when its frame arrived
        self._frames = 0
        self._frames_held = 0
        # Set while the disk refuses (the writer thread's own): what is queued is dropped, and a
        # new file is tried each drain.
        self._failing = False
        self._dropped_failing = 0
        self._fell_behind = False
        try:
            settings.folder.mkdir(parents=True, exist_ok=True)
            self._open(clock())
        except OSError as exc:
            raise RecorderError(
                f"cannot record into {settings.folder}: {exc.strerror or exc}"
            ) from exc
        self._thread.start()

    # --- the agent's side: stamp and queue, never wait --------------------------------------

    def on_event(self, event: AnyEvent) -> None:
        """An event-log listener: queue the kinds that are recorded."""
        started = time.thread_time()
        if type(event) in recording.EVENT_CHANNELS:
            self._put("event", event)
        if isinstance(event, GoalApplied):
            self._image_for_goal(event)
        self._loop_cpu_s += time.thread_time() - started

    def record(self, topic: str, log_ns: int, message: Any) -> None:
        """Queue ``message`` for one of the ``extra`` channels: a JSON object, or anything with
        ``encode()`` (an SDK message); ``log_ns`` is the message's own time (its log time is when
        it was queued, so that log times never go back)."""
        started = time.thread_time()
        self._put("extra", (topic, message))
        self._loop_cpu_s += time.thread_time() - started

    async def record_video(self, track: MediaStreamTrack) -> None:
        """Hold ``track``'s recent frames and queue them at the recording rate (a goal's own
        frame when one names it, see :meth:`on_event`), until cancelled or the track ends."""
        try:
            while True:
                frame = await track.recv()
                started = time.thread_time()
                if isinstance(frame, av.VideoFrame):
                    self._hold(frame)
                self._loop_cpu_s += time.thread_time() - started
        except Exception as exc:  # MediaStreamError and whatever the source raises
            log.info("recording the camera stopped: %s", exc or type(exc).__name__)

    def _hold(self, frame: av.VideoFrame) -> None:
        now = self._clock()
        self._frames += 1
        holding_from = self._due_ns - self._lead_ns
        # Frames no search can take any more: kept or older than the last image kept (images go
        # forward in time), too old, or from before the lead of the image now due.
        oldest = max(self._kept_ns + 1, now - HOLD_NS, holding_from)
        while self._held and self._held[0].arrived_ns < oldest:
            self._held.popleft()
        if now < holding_from:
            return  # not held: the camera's own pipeline lets go of it
        self._held.append(_Held(now, frame))
        self._frames_held += 1
        # No goal took this period's image within the period: the newest frame does, and the
        # next period holds from a second before, to find a slow link's goals again.
        if now >= self._due_ns + self._period_ns:
            self._lead_ns = HOLD_NS
            self._keep_image(self._held[-1], now)

    def _image_for_goal(self, goal: GoalApplied) -> None:
        now = self._clock()
        if now < self._due_ns or goal.frame is None:
            return
        for held in reversed(self._held):
            if held.arrived_ns <= self._kept_ns:
                return  # images go forward in time, as the camera did
            if held.tag == goal.frame:
                self._lead_ns = min(HOLD_NS, now - held.arrived_ns + LEAD_MARGIN_NS)
                self._keep_image(held, now)
                return

    def _keep_image(self, held: _Held, now: int) -> None:
        # Paced from the due time, not from now, so that the rate holds on a jittery source;
        # from now after a gap (the first frame, a stalled camera).
        behind = self._due_ns <= now - self._period_ns
        self._due_ns = (now if behind else self._due_ns) + self._period_ns
        # Stamped when the frame arrived: the image sits beside the pose the turtle had then.
        self._kept_ns = held.arrived_ns
        self._put("image", held, held.arrived_ns)

    def _put(
        self, kind: Literal["image", "event", "extra"], payload: Any, log_ns: int | None = None
    ) -> None:
        if not self._thread.is_alive():  # closed, or stopped by a fault it logged
            self.dropped += 1
            return
        if len(self._queue) >= QUEUE_LIMIT:
            if not self._fell_behind:
                log.warning("flight recorder falling behind: dropping what it cannot write")
                self._fell_behind = True
            self.dropped += 1
            return
        self._queue.append((kind, self._clock() if log_ns is None else log_ns, payload))

    async def close(self) -> None:
        """Write what is queued, finish the file and stop the writer thread."""
        await asyncio.to_thread(self._stop)

    def totals(self) -> RecorderTotals:
        """What was recorded and what it cost, as the event the agent logs when the recorder
        stops. Not counted: the camera relay's hand-over of each frame to the recorder's tap."""
        loop, writer = self._loop_cpu_s, self._writer_cpu_s
        return RecorderTotals(
            images=self.images,
            messages=self.messages,
            dropped=self.dropped,
            files=len(self.files),
            frames=self._frames,
            frames_held=self._frames_held,
            cpu_s=round(loop + writer, 4),
            loop_cpu_s=round(loop, 4),
            writer_cpu_s=round(writer, 4),
            seconds=round(time.monotonic() - self._started_s, 3),
            t=time.monotonic(),
        )

    def _stop(self) -> None:
        self._stopping.set()
        self._thread.join()

    # --- the writer thread ------------------------------------------------------------------

    def _write_all(self) -> None:
        try:
            while True:
                stopping = self._stopping.wait(DRAIN_PERIOD_S)
                self._drain()
                self._writer_cpu_s = time.thread_time()
                if stopping:
                    break
        except Exception:
            # Not the disk (that is _fail's): a fault of the recorder's own, which must not
            # stop the vehicle; the recording stops here.
            log.exception("flight recorder stopped")
            self._failing = True
        finally:
            try:
                self._finish()
            except OSError as exc:
                # Stopping: nothing more will come to drop or to resume for.
                path = self.files[-1] if self.files else self.settings.folder
                log.warning(
                    "flight recorder cannot finish %s (%s); its whole chunks stay readable",
                    path,
                    exc.strerror or exc,
                )
                self._close_file()

    def _drain(self) -> None:
        """Write what is queued; while the disk refuses, drop it and try a new file."""
        if self._failing and not self._resume():
            self._drop_queued()
            return
        while self._queue:
            kind, log_ns, payload = self._queue.popleft()
            try:
                if kind == "image":
                    self._write(recording.IMAGE_TOPIC, log_ns, self._image(payload, log_ns))
                    self.images += 1
                elif kind == "extra":
                    topic, message = payload
                    self._write(topic, log_ns, message)
                else:
                    topic = recording.EVENT_CHANNELS[type(payload)].topic
                    self._write(topic, log_ns, recording.message(payload))
            except OSError as exc:
                self.dropped += 1
                self._fail(exc)
                self._drop_queued()
                return

    def _fail(self, exc: OSError) -> None:
        """The disk refused a write: say so once, leave the file as far as it got (whole
        chunks read back), and write nothing more until a new file can be opened."""
        path = self.files[-1] if self.files else self.settings.folder
        log.warning(
            "flight recorder cannot write %s (%s): dropping what it records until it can "
            "write again, then a new file; what the file holds so far stays readable",
            path,
            exc.strerror or exc,
        )
        self._failing = True
        self._writer = None  # its unwritten chunk is lost with it
        self._close_file()

    def _resume(self) -> bool:
        """A new file, if the disk takes one now."""
        try:
            self._open(self._clock())
        except OSError:
            return False
        self._failing = False
        log.info(
            "flight recorder writing again, to %s (%d items dropped while it could not)",
            self.files[-1],
            self._dropped_failing,
        )
        self._dropped_failing = 0
        return True

    def _drop_queued(self) -> None:
        while self._queue:
            self._queue.popleft()
            self.dropped += 1
            self._dropped_failing += 1

    def _image(self, held: _Held, log_ns: int) -> dict[str, Any]:
        jpeg = encode_jpeg(held.frame, self.settings.jpeg_quality)
        return {
            "timestamp": {"sec": log_ns // 1_000_000_000, "nsec": log_ns % 1_000_000_000},
            "frame_id": "camera",
            "format": "jpeg",
            "data": base64.b64encode(jpeg).decode("ascii"),
            "frame": held.tag,
        }

    def _write(self, topic: str, log_ns: int, message: Any) -> None:
        writer = self._writer_for(log_ns)
        if isinstance(message, dict):
            data = json.dumps(message, separators=(",", ":")).encode()
        else:
            data = message.encode()
        writer.add_message(self._channels[topic], log_time=log_ns, data=data, publish_time=log_ns)
        self.messages += 1
        self._bytes += len(data)

    def _writer_for(self, now_ns: int) -> Writer:
        """The open file's writer; a new file when the current one is too big or too old."""
        limits = self.settings
        if self._writer is not None:
            # Counted before compression (the writer holds a chunk back until it is full): a
            # file ends up no larger than the limit.
            too_big = self._bytes >= limits.max_mb * 1e6
            too_old = now_ns - self._opened_ns >= limits.max_minutes * 60e9
            if not (too_big or too_old):
                return self._writer
            self._finish()
        return self._open(now_ns)

    def _open(self, now_ns: int) -> Writer:
        """A new file, its header and schemas written through to the disk, so that a folder
        or a disk that refuses is found here (the file removed again), not a chunk later."""
        stamp = datetime.fromtimestamp(now_ns / 1e9, UTC).strftime("%Y%m%dT%H%M%S.%fZ")
        room = "".join(c if c.isalnum() or c in "-_" else "_" for c in self.settings.room)
        path = self.settings.folder / f"autopilot-{room}-{stamp}.mcap"
        file = path.open("wb")
        try:
            writer = Writer(
                file, chunk_size=self.settings.chunk_bytes, compression=CompressionType.ZSTD
            )
            writer.start(profile="", library="webrtc-autopilot flight recorder")
            channels = {}
            for topic, schema in recording.channels():
                schema_id = writer.register_schema(
                    name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
                )
                channels[topic] = writer.register_channel(
                    topic=topic, message_encoding="json", schema_id=schema_id
                )
            for extra in self._extra:
                schema_id = writer.register_schema(
                    name=extra.schema, encoding=extra.schema_encoding, data=extra.schema_data
                )
                channels[extra.topic] = writer.register_channel(
                    topic=extra.topic, message_encoding=extra.encoding, schema_id=schema_id
                )
            file.flush()
        except OSError:
            with contextlib.suppress(OSError):
                file.close()
            with contextlib.suppress(OSError):
                path.unlink()
            raise
        self._file, self._writer, self._channels = file, writer, channels
        self._opened_ns = now_ns
        self._bytes = 0
        self.files.append(path)
        log.info("recording to %s", path)
        self._prune()
        return writer

    def _prune(self) -> None:
        """Keep the newest ``max_files`` recordings of this run."""
        while len(self.files) > self.settings.max_files:
            oldest = self.files.pop(0)
            log.warning("removing the oldest recording %s (keeping %d)", oldest, len(self.files))
            oldest.unlink(missing_ok=True)

    def _finish(self) -> None:
        """Write the open file's summary and close it; OSError when the disk refuses."""
        writer, self._writer = self._writer, None
        if writer is not None:
            writer.finish()  # type: ignore[no-untyped-call]  # mcap leaves it unannotated
        self._close_file()

    def _close_file(self) -> None:
        file, self._file = self._file, None
        if file is not None:
            # What closing flushes may be refused too: the file keeps what the disk took.
            with contextlib.suppress(OSError):
                file.close()
