"""``autopilot vehicle --foxglove``: the official client (``@foxglove/ws-protocol`` in Node, as
Foxglove connects) reads a running agent's every channel, each message valid against
``@foxglove/schemas`` or its channel's JSON Schema; the image decodes at the camera's size, the
annotations fall inside it, the transforms chain ``camera`` → ``base_link`` → ``odom`` and each
Twist turns toward its goal's side. No viewer can publish, a viewer that never reads does not
stop the vehicle, and with tokens asked for the network is served only over TLS
(``test_foxglove_gate.py``: behind a token).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import re
import shutil
import subprocess
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest

from app import recording
from app.protocol import events as ev
from app.protocol.robot import PRESETS
from app.recording import EVENT_CHANNELS
from app.server.serve import RunningServer
from app.tools.bench.foxglove import PilotedAgent
from app.tools.bench.foxglove_viewer import stuck_viewer
from tests.helpers.recordings import record
from tests.helpers.waiting import eventually
from vehicle_agent import foxglove
from vehicle_agent.foxglove import Address
from vehicle_agent.recorder import FlightRecorder, RecordSettings

HERE = Path(__file__).parent
REPO = HERE.parents[1]
W, H = 320, 240
# The robot has a camera (so a calibration too), as the diffdrive room's robot does: the
# PilotedAgent's.
ROBOT = PRESETS["diffdrive"]
GOAL = EVENT_CHANNELS[ev.GoalApplied].topic
TWIST = EVENT_CHANNELS[ev.TwistSent].topic
MODE = EVENT_CHANNELS[ev.ModeChanged].topic
POSE = EVENT_CHANNELS[ev.PoseReport].topic
EVERY_TOPIC = [
    foxglove.IMAGE_TOPIC,
    foxglove.ANNOTATIONS_TOPIC,
    foxglove.CALIBRATION_TOPIC,
    foxglove.POSE_TOPIC,
    foxglove.TF_TOPIC,
    foxglove.LOG_TOPIC,
    foxglove.HEALTH_TOPIC,
    GOAL,
    TWIST,
    MODE,
    POSE,
]
SCHEMAS = {
    foxglove.IMAGE_TOPIC: "foxglove.CompressedImage",
    foxglove.ANNOTATIONS_TOPIC: "foxglove.ImageAnnotations",
    foxglove.CALIBRATION_TOPIC: "foxglove.CameraCalibration",
    foxglove.POSE_TOPIC: "foxglove.PoseInFrame",
    foxglove.TF_TOPIC: "foxglove.FrameTransforms",
    foxglove.LOG_TOPIC: "foxglove.Log",
    foxglove.HEALTH_TOPIC: "autopilot.Health",
}


async def view(
    url: str,
    timeout_s: float = 10,
    twists: int = 7,
    flood: int = 0,
    topics: Sequence[str] = EVERY_TOPIC,
    ca: Path | None = None,
) -> dict[str, Any]:
    """What the official client saw (foxglove_viewer.mjs), once every one of ``topics`` came;
    ``ca``: the CA to trust for a ``wss://`` URL."""
    node = shutil.which("node")
    assert node is not None, "Node.js runs the official Foxglove client"
    options = {
        "url": url,
        "topics": list(topics),
        "timeoutS": timeout_s,
        "twists": twists,
        "flood": flood,
        "goalTopic": GOAL,
        "twistTopic": TWIST,
    }
    if ca is not None:
        options["ca"] = str(ca)
    process = await asyncio.create_subprocess_exec(
        node,
        str(HERE / "foxglove_viewer.mjs"),
        json.dumps(options),
        cwd=REPO,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(process.communicate(), timeout_s + 10)
    assert process.returncode == 0, err.decode()
    result: dict[str, Any] = json.loads(out.decode().splitlines()[-1])
    return result


def check_view(
    result: dict[str, Any], expected: Sequence[str] = EVERY_TOPIC, size: tuple[int, int] = (W, H)
) -> None:
    """Every channel expected arrived, every message valid, and what they show is consistent
    (the camera's ``size``)."""
    width, height = size
    assert result["error"] is None, result
    topics = result["topics"]
    for topic in expected:
        assert topics[topic]["messages"] > 0, (topic, topics)
    for topic, entry in topics.items():
        assert entry["problems"] == [], (topic, entry)
    for topic, schema in SCHEMAS.items():
        assert topics[topic]["schema"] == schema
    # Typed channels go as protobuf (Foxglove's own), the recording's as JSON with JSON Schema.
    assert topics[foxglove.IMAGE_TOPIC]["encoding"] == "protobuf"
    assert topics[TWIST]["encoding"] == topics[GOAL]["encoding"] == "json"
    assert result["imageSizes"] == [f"{width}x{height}"]
    points = result["annotationPoints"]
    assert points
    for point in points:
        assert 0 <= point.get("x", 0) <= width and 0 <= point.get("y", 0) <= height, point
    assert result["cameraChain"] == ["camera", "base_link", "odom"]
    # Most Twists turn toward the side of their goal's target (foxglove_viewer.mjs says why not
    # every one must); a turn of the wrong sign would turn none of them so.
    sides = result["twistSides"]
    assert len(sides) >= 7
    toward = [(side["angular"] > 0) == side["left"] for side in sides]
    assert sum(toward) > len(toward) / 2, sides


async def test_the_official_client_reads_every_channel_valid(server: RunningServer) -> None:
    async with PilotedAgent(server.url, toggle_mode=True).running() as live:
        result = await view(live.url)
    check_view(result)
    # No capability: a viewer can neither publish nor call anything, so it cannot drive.
    assert result["capabilities"] == []


async def test_nothing_is_encoded_for_a_channel_without_a_viewer(server: RunningServer) -> None:
    piloted = PilotedAgent(server.url, toggle_mode=True)
    async with piloted.running() as live:
        await eventually(lambda: bool(piloted.twists), 10, "a Twist")
        await asyncio.sleep(0.5)
        assert live.images == 0
        result = await view(live.url)
        check_view(result)
        assert live.images > 0


@pytest.mark.slow
async def test_hostile_viewers_do_not_stop_the_vehicle(server: RunningServer) -> None:
    """A viewer that subscribes to everything and never reads, and one that floods subscribe and
    unsubscribe: the vehicle still handles every goal, and a fair viewer still reads everything."""
    piloted = PilotedAgent(server.url, toggle_mode=True)
    async with piloted.running() as live:
        async with stuck_viewer(live.url, len(EVERY_TOPIC)):
            before = len(piloted.goals)
            result = await view(live.url, flood=50)
            sent = set(piloted.goals[before:])
            assert len(sent) >= 10
            # Every goal sent meanwhile is handled (the last ones arrive 30 ms later).
            await eventually(lambda: sent <= piloted.handled, 5, "every goal handled")
    check_view(result)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("8765", Address("127.0.0.1", 8765)),
        ("0.0.0.0:9000", Address("0.0.0.0", 9000)),
        ("[::1]:9000", Address("::1", 9000)),
        ("localhost:0", Address("localhost", 0)),
    ],
)
def test_address_is_host_and_port_on_loopback_by_default(text: str, expected: Address) -> None:
    assert foxglove.address(text) == expected


@pytest.mark.parametrize("text", ["", ":80", "host:", "host:70000", "x"])
def test_a_malformed_address_is_refused(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError):
        foxglove.address(text)


def test_the_network_is_served_with_a_secret_only_over_tls() -> None:
    loopback, network = Address("127.0.0.1", 1), Address("0.0.0.0", 1)
    assert foxglove.exposure_error(loopback, secret_set=True, tls=False) is None
    assert foxglove.exposure_error(network, secret_set=False, tls=False) is None
    assert foxglove.exposure_error(network, secret_set=True, tls=True) is None
    refused = foxglove.exposure_error(network, secret_set=True, tls=False)
    assert (
        refused is not None and "AUTOPILOT_SECRET" in refused and "--foxglove-certfile" in refused
    )


def test_a_locked_target_is_drawn_in_its_own_colour() -> None:
    emitted: list[tuple[str, Any]] = []
    scene = foxglove.Scene(ROBOT, lambda topic, _, m: emitted.append((topic, m)), lambda t: True)
    box = {"op": "face", "frame": None, "x": 160.0, "y": 120.0, "w": W, "h": H, "box_w": 40.0}
    for seq, locked in ((1, False), (2, True)):
        scene.on_event(ev.GoalApplied(seq=seq, **box, box_h=50.0, locked=locked, t=float(seq)))
    drawn = [m for topic, m in emitted if topic == foxglove.ANNOTATIONS_TOPIC]
    assert len(drawn) == 2

    # The SDK's messages show their fields only in their text (Rust's Debug form).
    outline = re.compile(
        r"(?:outline_color|text_color): Some\(Color \{ r: ([-\d.]+), g: ([-\d.]+), b: ([-\d.]+),"
        r" a: ([-\d.]+) \}\)"
    )

    def colours(annotations: Any) -> set[tuple[float, ...]]:
        """The colours of the box's and the point's outline and of the label's text."""
        found = outline.findall(repr(annotations))
        assert len(found) == 3, repr(annotations)  # the point, the box, the label
        return {tuple(float(c) for c in rgba) for rgba in found}

    assert colours(drawn[0]) == {foxglove.TARGET_COLOUR}
    assert colours(drawn[1]) == {foxglove.LOCKED_COLOUR} != {foxglove.TARGET_COLOUR}
    assert 'text: "face #1"' in repr(drawn[0]) and 'text: "face #2 locked"' in repr(drawn[1])


def test_a_recording_has_the_same_channels_and_an_outside_reader_validates_them(
    tmp_path: Path,
) -> None:
    settings = RecordSettings(tmp_path, room="test", fps=10)
    flight = FlightRecorder(settings, extra=foxglove.recorded_channels())
    scene = foxglove.recording_scene(flight, ROBOT)
    asyncio.run(record(settings, 1.2, flight, listeners=[scene.on_event]))
    node = shutil.which("node")
    assert node is not None
    done = subprocess.run(
        [node, str(HERE / "mcap_reader.mjs"), *map(str, flight.files)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert done.returncode == 0, done.stderr
    topics = json.loads(done.stdout.splitlines()[-1])
    # The live view's channels, with the same schemas (and the recording's own, as before).
    for topic, schema in SCHEMAS.items():
        assert topics[topic]["schema"] == schema, topic
    for topic in (foxglove.ANNOTATIONS_TOPIC, foxglove.CALIBRATION_TOPIC, foxglove.POSE_TOPIC):
        assert topics[topic]["messages"] > 0, topic
    for topic in (foxglove.TF_TOPIC, foxglove.HEALTH_TOPIC, foxglove.IMAGE_TOPIC, GOAL, TWIST):
        assert topics[topic]["messages"] > 0, topic
    for topic, entry in topics.items():
        assert entry["problems"] == [], (topic, entry)
    # autopilot replay still reads it: its goals and images by frame tag, its JSON messages,
    # and every channel counted.
    assert any(True for _ in recording.events(flight.files))
    assert any(frame is not None for frame, _ in recording.images(flight.files))
    json_topics = {topic for topic, _, _ in recording.messages(flight.files)}
    assert foxglove.HEALTH_TOPIC in json_topics and foxglove.POSE_TOPIC not in json_topics
    counted = recording.summary(flight.files)["channels"]
    assert {t: c["messages"] for t, c in counted.items()} == {
        t: e["messages"] for t, e in topics.items() if e["messages"]
    }
