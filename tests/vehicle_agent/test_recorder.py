"""The flight recorder's files, read back with the ``mcap`` reader: every channel with its
Foxglove-readable schema, the counts that went in, log times that never go back, JPEG images
that decode at the camera's size with their frame tags, and files that roll over and are pruned.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from aiortc.mediastreams import MediaStreamError
from mcap.reader import make_reader

from app import recording
from app.protocol import events as ev
from app.protocol import frametag
from app.recording import EVENT_CHANNELS, IMAGE_SCHEMA, IMAGE_TOPIC
from tests.helpers.agent import Vehicle
from vehicle_agent import cli as agent_cli
from vehicle_agent import recorder
from vehicle_agent.core.control import PROFILES
from vehicle_agent.events import EventLog
from vehicle_agent.recorder import FlightRecorder, RecordSettings
from vehicle_agent.video import SyntheticVideo

FPS = 30.0
RECORD_FPS = 10.0
GOALS = EVENT_CHANNELS[ev.GoalApplied].topic


def _goal(seq: int, t: float) -> ev.GoalApplied:
    """A goal for frame ``seq`` (the frame tags count the camera's frames)."""
    return ev.GoalApplied(seq=seq, op="face", frame=seq, x=100.0, y=200.0, w=640, h=480, t=t)


def _read(path: Path) -> tuple[dict[str, tuple[str, str, str]], list[tuple[str, int, Any]]]:
    """Channels (topic → schema name, schema encoding, message encoding) and messages."""
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        channels = {
            channel.topic: (
                summary.schemas[channel.schema_id].name,
                summary.schemas[channel.schema_id].encoding,
                channel.message_encoding,
            )
            for channel in summary.channels.values()
        }
        messages = [
            (channel.topic, message.log_time, json.loads(message.data))
            # In the order written, not sorted: the check that log times never go back.
            for _, channel, message in reader.iter_messages(log_time_order=False)
        ]
    return channels, messages


async def _record(settings: RecordSettings, seconds: float) -> FlightRecorder:
    """Record a synthetic camera and a few of each event for ``seconds``."""
    recorder = FlightRecorder(settings)
    events = EventLog()
    events.listeners.append(recorder.on_event)
    video = SyntheticVideo(fps=FPS)
    camera = asyncio.create_task(recorder.record_video(video))
    for seq in range(1, 6):
        events.emit(_goal(seq, t=seq / 10))
        events.emit(ev.TwistSent(seq=seq, frame=seq, linear=0.5, angular=-0.25, t=seq / 10))
        events.emit(ev.PoseReport(x=5.5, y=5.5, theta=1.57, sent=True, t=seq / 10))
        # Not recorded: the event log's only.
        events.emit(ev.FrameSent(frame=seq, face_x=1.0, face_y=2.0, t=seq / 10))
    events.emit(ev.GoalDropped(seq=3, frame=3, why="old", t=1.0))
    events.emit(ev.ModeChanged(mode="manual", operator="ann", t=1.0))
    events.emit(ev.DriveReceived(seq=1, applied=True, moving=True, t=1.0))
    events.emit(ev.SearchStarted(side="left", t=1.0))
    events.emit(ev.SearchEnded(why="found", after_s=0.5, t=1.5))
    events.emit(
        ev.LinkChanged(state="up", relay="relay", local_candidates=("host",), selected="host", t=1)
    )
    await asyncio.sleep(seconds)
    camera.cancel()
    video.stop()
    await recorder.close()
    return recorder


@dataclass
class Recorded:
    """A recording of :func:`_record` and the wall clock (ns) when it started and ended."""

    recorder: FlightRecorder
    folder: Path
    started_ns: int
    ended_ns: int


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    """One recording of 1.5 s, read by the tests that only read it."""
    folder = tmp_path_factory.mktemp("recorded")
    started_ns = time.time_ns()
    recorder = asyncio.run(_record(RecordSettings(folder, room="lab", fps=RECORD_FPS), 1.5))
    return Recorded(recorder, folder, started_ns, time.time_ns())


def test_a_recording_reads_back_with_its_schemas_counts_times_and_images(
    recorded: Recorded,
) -> None:
    recorder = recorded.recorder
    files = sorted(recorded.folder.glob("autopilot-lab-*.mcap"))
    assert files == recorder.files and len(files) == 1
    channels, messages = _read(files[0])

    assert channels[IMAGE_TOPIC] == (IMAGE_SCHEMA, "jsonschema", "json")
    assert set(channels) == {IMAGE_TOPIC, *(c.topic for c in EVENT_CHANNELS.values())}
    assert all(encodings == "jsonschema" for _, encodings, _ in channels.values())

    counts: dict[str, int] = {}
    for topic, _, _ in messages:
        counts[topic] = counts.get(topic, 0) + 1
    assert counts[GOALS] == 5
    assert counts[EVENT_CHANNELS[ev.TwistSent].topic] == 5
    assert counts[EVENT_CHANNELS[ev.PoseReport].topic] == 5
    once = (ev.GoalDropped, ev.ModeChanged, ev.DriveReceived, ev.SearchStarted, ev.SearchEnded)
    for kind in (*once, ev.LinkChanged):
        assert counts[EVENT_CHANNELS[kind].topic] == 1, kind
    # 1.5 s of a 30 fps camera at 10 images a second (fewer if a loaded machine delays frames).
    assert 5 <= counts[IMAGE_TOPIC] <= 16, counts
    assert recorder.images == counts[IMAGE_TOPIC] and recorder.dropped == 0
    # What the recorder counts of itself: the same images and messages, and the CPU they took.
    totals = recorder.totals()
    assert totals.images == recorder.images and totals.messages == len(messages)
    assert totals.dropped == 0 and totals.files == 1 and totals.seconds >= 1.5
    assert 0 < totals.writer_cpu_s < totals.cpu_s < totals.seconds, totals

    # On each channel, in the order written (an image is stamped when its frame arrived, a
    # moment before it was chosen, so channels interleave).
    for channel in channels:
        times = [log_time for topic, log_time, _ in messages if topic == channel]
        assert times == sorted(times), channel

    goal = next(fields for topic, _, fields in messages if topic == GOALS)
    assert goal == {
        "seq": 1,
        "op": "face",
        "frame": 1,
        "x": 100.0,
        "y": 200.0,
        "w": 640,
        "h": 480,
        "box_w": None,
        "box_h": None,
        "locked": False,
        "t": 0.1,
    }
    # Read back typed, every recorded event is the one emitted.
    recorded = [event for _, event in recording.events(files)]
    assert recorded[0] == _goal(1, t=0.1)
    assert {type(event) for event in recorded} == set(EVENT_CHANNELS)
    images = [fields for topic, _, fields in messages if topic == IMAGE_TOPIC]
    camera_video = SyntheticVideo(fps=FPS)
    tags = []
    for image in images:
        assert image["format"] == "jpeg"
        jpeg = np.frombuffer(base64.b64decode(image["data"]), np.uint8)
        bgr = cv2.imdecode(jpeg, cv2.IMREAD_COLOR)
        assert bgr is not None and bgr.shape == (480, 640, 3)
        # The tag survives the JPEG: the image is the frame its "frame" field names, in its
        # own colours (channels in the wrong order would be far off the camera's frame).
        rgb = np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), np.uint8)
        assert frametag.read(rgb) == image["frame"]
        camera = camera_video.render(image["frame"]).astype(np.int16)
        assert np.abs(rgb.astype(np.int16) - camera).mean() < 4
        tags.append(image["frame"])
    # Never two camera frames in a row, and no more than 10 images a second on average.
    assert min(b - a for a, b in zip(tags, tags[1:], strict=False)) >= 2, tags
    stamps = [t for topic, t, _ in messages if topic == IMAGE_TOPIC]
    assert (stamps[-1] - stamps[0]) / (len(stamps) - 1) >= 0.095e9, stamps


def test_images_are_stamped_in_seconds_on_the_clock_of_the_events(recorded: Recorded) -> None:
    # An image's header stamp (seconds and nanoseconds, as foxglove.CompressedImage has it) is
    # its log time, the wall clock when its frame arrived: inside the recording's run, beside
    # the events logged in it (and so beside the pose the turtle had then).
    _, messages = _read(recorded.recorder.files[0])
    images = [(log_time, fields) for topic, log_time, fields in messages if topic == IMAGE_TOPIC]
    assert images
    for log_time, fields in images:
        stamp = fields["timestamp"]
        assert 0 <= stamp["nsec"] < 1_000_000_000
        assert stamp["sec"] * 1_000_000_000 + stamp["nsec"] == log_time
        assert recorded.started_ns <= log_time <= recorded.ended_ns
    events = [log_time for topic, log_time, _ in messages if topic != IMAGE_TOPIC]
    assert all(recorded.started_ns <= t <= recorded.ended_ns for t in events)
    # The events were logged at the start, the images over the 1.5 s that followed.
    assert 0 <= images[0][0] - min(events) < 1_000_000_000


# Each recording's log times (seconds from its start) by file: with the default limit (an hour,
# --record-max-minutes 60) and with 1.5 minutes.
ROLL_OVER = [
    ({}, [[0.0, 60.0, 3599.9], [3600.0, 7199.0], [7200.0]]),
    ({"max_minutes": 1.5}, [[0.0, 60.0, 89.9], [90.0, 179.0], [180.0]]),
]


@pytest.mark.parametrize(("limits", "files_s"), ROLL_OVER)
def test_a_file_rolls_over_at_its_age_and_not_before(
    tmp_path: Path, limits: dict[str, float], files_s: list[list[float]]
) -> None:
    # On an injected clock: what is logged a moment before a file reaches its age limit goes in
    # it, and what comes at the limit starts the next file.
    start_ns = 1_800_000_000 * 1_000_000_000
    now = [start_ns]
    recorder = FlightRecorder(RecordSettings(tmp_path, room="lab", **limits), clock=lambda: now[0])
    events = EventLog()
    events.listeners.append(recorder.on_event)
    for offset_s in (t for file in files_s for t in file):
        now[0] = start_ns + round(offset_s * 1e9)
        events.emit(ev.ModeChanged(mode="manual", operator="ann", t=offset_s))
    asyncio.run(recorder.close())
    logged = [
        [(log_time - start_ns) / 1e9 for _, log_time, _ in _read(path)[1]]
        for path in recorder.files
    ]
    assert logged == files_s


async def test_the_agents_drive_commands_are_recorded(tmp_path: Path) -> None:
    # The agent's own events reach the recorder: an operator takes the wheel and drives; each
    # drive command is on /autopilot/drive, applied or not, moving or not.
    vehicle = Vehicle("default")
    recorder = FlightRecorder(RecordSettings(tmp_path, room="lab"))
    vehicle.agent.events.listeners.append(recorder.on_event)
    for text in (
        '{"type": "mode", "mode": "manual", "operator": "ann"}',
        '{"type": "drive", "seq": 1, "linear": 1, "angular": 0}',
        '{"type": "drive", "seq": 1, "linear": 1, "angular": 0}',  # again: not the newest
        '{"type": "drive", "seq": 2, "linear": 0, "angular": 0}',  # let go: applied, stops
    ):
        assert vehicle.agent.handle_channel_message(text, "relay") is None
    await recorder.close()
    _, messages = _read(recorder.files[0])
    by_topic: dict[str, list[Any]] = {}
    for topic, _, fields in messages:
        # Without the time the agent stamped it with, which the test cannot know.
        by_topic.setdefault(topic, []).append({k: v for k, v in fields.items() if k != "t"})
    assert by_topic[EVENT_CHANNELS[ev.DriveReceived].topic] == [
        {"seq": 1, "applied": True, "moving": True},
        {"seq": 1, "applied": False, "moving": False},
        {"seq": 2, "applied": True, "moving": False},
    ]
    assert by_topic[EVENT_CHANNELS[ev.ModeChanged].topic] == [{"mode": "manual", "operator": "ann"}]
    manual = PROFILES["default"].manual_linear
    twists = by_topic[EVENT_CHANNELS[ev.TwistSent].topic]
    assert [(t["linear"]["x"], t["angular"]["z"]) for t in twists] == [
        (0.0, 0.0),  # taking over stops first
        (manual, 0.0),
        (0.0, 0.0),
    ]


class _Camera:
    """A synthetic camera on the recorder's own clock, ``fps`` frames a second for ``seconds``:
    each frame is handed over at its time, after the goals a relay sent by then, 60 ms after
    the frames they name (every other frame). Nothing waits on wall time: a loaded machine
    runs the same sequence of frames and goals."""

    def __init__(self, fps: float, seconds: float) -> None:
        self.video = SyntheticVideo(320, 240, fps=fps)
        self.fps, self.frames = fps, round(seconds * fps)
        self.now_ns = 0
        self.index = 0
        self.recorder: FlightRecorder | None = None

    def clock(self) -> int:
        return self.now_ns

    def _at_ns(self, seconds: float) -> int:
        return round(seconds * 1e9)

    async def recv(self) -> Any:
        if self.index == self.frames:
            raise MediaStreamError("the camera's clip ended")
        self.now_ns = self._at_ns(self.index / self.fps)
        assert self.recorder is not None
        for named in range(0, self.index, 2):
            sent_s = named / self.fps
            arrives_ns = self._at_ns(sent_s + 0.06)
            if self.now_ns - self._at_ns(1 / self.fps) < arrives_ns <= self.now_ns:
                self.recorder.on_event(_goal(named, t=sent_s + 0.06))
        frame = await self.video.make_frame(self.index)
        self.index += 1
        return frame


async def _record_on_a_clock(folder: Path, fps: float, seconds: float) -> FlightRecorder:
    camera = _Camera(FPS, seconds)
    flight = FlightRecorder(RecordSettings(folder, room="lab", fps=fps), clock=camera.clock)
    camera.recorder = flight
    await flight.record_video(camera)  # type: ignore[arg-type]
    await flight.close()
    return flight


def test_the_images_kept_are_the_frames_goals_were_sent_for(tmp_path: Path) -> None:
    recorder = asyncio.run(_record_on_a_clock(tmp_path, fps=10, seconds=2.0))
    _, messages = _read(recorder.files[0])
    goals = {fields["frame"] for topic, _, fields in messages if topic == GOALS}
    tags = [fields["frame"] for topic, _, fields in messages if topic == IMAGE_TOPIC]
    # The first image is due before any goal; every later one is a frame a goal named (half
    # the camera's frames: sampled by time alone, half the images would not be).
    assert len(tags) >= 10, tags
    assert all(tag in goals for tag in tags[1:]), (tags, sorted(goals))
    assert tags == sorted(tags)  # never a frame older than the last one kept


def test_frames_are_held_only_from_shortly_before_an_image_is_due(tmp_path: Path) -> None:
    # Two images a second from a 30 fps camera, goals 60 ms late: after the first period (held
    # whole, no goal delay known yet), each period of 15 frames holds those from the goals' delay
    # and a margin before it is due until a goal names one, about 6; not every frame.
    recorder = asyncio.run(_record_on_a_clock(tmp_path, fps=2, seconds=3.0))
    totals = recorder.totals()
    # Two images a second for three seconds; the first period's 15 frames held whole, then a
    # few before each image is due: well under half of the 90.
    assert totals.images == 6 and totals.frames == 90, totals
    assert 15 < totals.frames_held <= 0.4 * totals.frames, totals
    _, messages = _read(recorder.files[0])
    goals = {fields["frame"] for topic, _, fields in messages if topic == GOALS}
    tags = [fields["frame"] for topic, _, fields in messages if topic == IMAGE_TOPIC]
    assert all(tag in goals for tag in tags[1:]), (tags, sorted(goals))


def test_files_roll_over_by_size_and_only_the_newest_are_kept(tmp_path: Path) -> None:
    # A few images fill 0.05 MB: a new file every few, and three kept.
    settings = RecordSettings(tmp_path, room="lab", fps=RECORD_FPS, max_mb=0.05, max_files=3)
    recorder = asyncio.run(_record(settings, 2.0))
    kept = sorted(tmp_path.glob("*.mcap"))
    assert len(recorder.files) == 3 and kept == sorted(recorder.files)
    for path in kept:
        channels, messages = _read(path)  # each file is complete on its own
        assert IMAGE_TOPIC in channels and messages


def test_the_options_are_checked_and_the_demo_passes_them_on_unchanged(tmp_path: Path) -> None:
    vehicle = argparse.ArgumentParser()
    agent_cli.add_arguments(vehicle)
    with pytest.raises(SystemExit):
        vehicle.parse_args(["--record", "x", "--record-quality", "0"])
    demo = argparse.ArgumentParser()
    recorder.add_arguments(demo)
    asked = demo.parse_args(["--record", str(tmp_path), "--record-fps", "5", "--record-keep", "2"])
    passed = vehicle.parse_args(recorder.arguments_of(asked))
    assert recorder.settings_from(passed, "r") == recorder.settings_from(asked, "r")
    assert recorder.settings_from(passed, "r") == RecordSettings(tmp_path, "r", 5.0, max_files=2)
    assert recorder.arguments_of(demo.parse_args([])) == []
