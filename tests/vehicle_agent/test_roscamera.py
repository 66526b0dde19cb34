"""``--video ros:TOPIC`` (vehicle_agent/roscamera.py): its rules, and the track against a
rosbridge of the test's own that sends what no real one would (bad frames, a refused CBOR).

The same track against the server's own ``/rosbridge``, with real publishers of both message
types, is tests/vehicle_agent/test_roscamera_rosbridge.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import time
from collections.abc import AsyncIterator
from typing import Any

import cv2
import numpy as np
import pytest

from app.protocol import frametag
from app.protocol.events import FrameSent
from app.protocol.robot import PRESETS
from app.resources import OPERATIONS_SPEC
from app.vision.reference import detect
from app.vision.spec import load_spec
from tests.helpers.camera_frames import as_json, compressed, pattern, pattern_error
from tests.helpers.stub_rosbridge import StubRosbridge, running
from tests.helpers.waiting import eventually
from vehicle_agent.rosbridge_client import RosbridgeClient
from vehicle_agent.roscamera import (
    CameraError,
    LatestSlot,
    RosCamera,
    blank_frame,
    camera_of,
    capture_time,
    topic_of,
)

TOPIC = "/camera/image/compressed"


# -- the rules ---------------------------------------------------------------------------------


def test_a_stamp_is_believed_up_to_two_seconds_old_and_never_from_the_future() -> None:
    at, wall = 500.0, 1_700_000_000.0
    assert capture_time(wall - 0.25, at, wall) == (pytest.approx(499.75), "stamp")
    assert capture_time(wall - 1.9, at, wall) == (pytest.approx(498.1), "stamp")
    assert capture_time(wall, at, wall) == (at, "stamp")
    assert capture_time(wall - 2.1, at, wall) == (at, "receipt")
    assert capture_time(wall + 0.05, at, wall) == (at, "receipt")  # a clock ahead of ours
    assert capture_time(0.0, at, wall) == (at, "receipt")  # no stamp at all
    assert capture_time(12.0, at, wall) == (at, "receipt")  # sim time


def test_the_slot_keeps_only_the_newest_and_counts_what_it_dropped() -> None:
    slot: LatestSlot[int] = LatestSlot()
    assert slot.take() is None
    for n in (1, 2, 3):
        slot.put(n)
    assert slot.take() == 3
    assert slot.take() is None
    slot.put(4)
    assert slot.take() == 4
    assert (slot.received, slot.dropped) == (4, 2)


def test_video_values_naming_a_topic() -> None:
    assert topic_of("ros:/camera/image_raw") == "/camera/image_raw"
    assert topic_of("ros:camera/image_raw") == "/camera/image_raw"
    assert topic_of("synthetic") is None
    assert topic_of("/dev/video0") is None
    with pytest.raises(CameraError, match="names no topic"):
        topic_of("ros:/")


def test_a_bare_ros_is_the_camera_of_the_robots_description() -> None:
    burger = PRESETS["turtlebot3"]
    assert camera_of("ros", burger) == (
        "/camera/image_raw/compressed",
        "sensor_msgs/CompressedImage",
    )
    # The description's type goes with its own topic; another topic's is learnt elsewhere.
    assert camera_of("ros:/camera/image_raw/compressed", burger) == (
        "/camera/image_raw/compressed",
        "sensor_msgs/CompressedImage",
    )
    assert camera_of("ros:/camera/image_raw", burger) == ("/camera/image_raw", None)
    assert camera_of("synthetic", burger) is None
    # A turtlesim has no camera topic: a bare ros says so, and how to name one.
    with pytest.raises(CameraError, match="turtlesim has no camera topic.*--video ros:/camera"):
        camera_of("ros", PRESETS["turtlesim"])


def test_the_no_camera_frame_gives_no_operation_a_target() -> None:
    spec = load_spec(OPERATIONS_SPEC)
    frame = blank_frame((640, 480), TOPIC)
    frametag.stamp(frame, 12345)
    rgba = cv2.cvtColor(frame, cv2.COLOR_RGB2RGBA)
    for operation in spec.operations:
        assert detect(operation, rgba).target is None, operation.id


# -- a rosbridge of the test's own -------------------------------------------------------------


@pytest.fixture
async def stub() -> AsyncIterator[StubRosbridge]:
    async with running(StubRosbridge()) as rosbridge:
        yield rosbridge


@contextlib.asynccontextmanager
async def started(stub: StubRosbridge, **options: Any) -> AsyncIterator[RosCamera]:
    """A camera subscribed through a connection of its own (the robot link's, in the agent)."""
    client = RosbridgeClient(stub.url)
    camera = RosCamera(client, TOPIC, **{"fps": 100, **options})
    try:
        await camera.start()
        await eventually(lambda: bool(stub.subscribes), 5, "the subscription")
        yield camera
    finally:
        camera.stop()
        await client.close()


def rgb(frame: Any) -> np.ndarray:
    return np.asarray(frame.to_ndarray(format="rgb24"))


def jpeg_msg(number: int, seconds: float | None = None) -> dict[str, Any]:
    stamp = time.time() if seconds is None else seconds
    return compressed(pattern(640, 480, number), "jpg", stamp)


async def test_no_camera_frames_before_the_first_picture_and_after_the_camera_falls_silent(
    stub: StubRosbridge, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger="vehicle_agent.roscamera")
    sent: list[FrameSent] = []
    async with started(stub, on_frame=sent.append) as camera:
        blank = blank_frame((640, 480), TOPIC)
        first = rgb(await camera.recv())
        assert np.array_equal(first[50:], blank[50:])  # all but the tag rows
        assert sent == []  # nothing was captured
        await stub.publish(TOPIC, jpeg_msg(7))
        await eventually(lambda: camera.slot.received == 1, 5, "the picture")
        picture = rgb(await camera.recv())
        assert pattern_error(picture) <= 12
        assert frametag.read(picture) == 1  # the track's own frame number
        assert [e.frame for e in sent] == [1] and sent[0].capture == "stamp"
        # The camera falls silent: after half a second, "no camera" again, said once.
        await asyncio.sleep(0.6)
        later = [rgb(await camera.recv()) for _ in range(3)]
        assert all(np.array_equal(f[50:], blank[50:]) for f in later)
        silent = [r for r in caplog.records if "sending 'no camera' frames" in r.message]
        assert len(silent) == 1
        # It comes back: the new picture, said once.
        await stub.publish(TOPIC, jpeg_msg(8))
        await eventually(lambda: camera.slot.received == 2, 5, "the second picture")
        assert pattern_error(rgb(await camera.recv())) <= 12
        assert any("frames again after" in r.message for r in caplog.records)


async def test_a_camera_slower_than_the_track_has_its_newest_picture_sent_again(
    stub: StubRosbridge,
) -> None:
    sent: list[FrameSent] = []
    async with started(stub, on_frame=sent.append) as camera:
        stamp = time.time()
        await stub.publish(TOPIC, jpeg_msg(3, stamp))
        await eventually(lambda: camera.slot.received == 1, 5, "the picture")
        frames = [rgb(await camera.recv()) for _ in range(3)]
        assert [frametag.read(f) for f in frames] == [0, 1, 2]
        # One picture, three frames: each its own number, all with the picture's time.
        assert [e.frame for e in sent] == [0, 1, 2]
        assert len({e.t for e in sent}) == 1
        assert camera.pictures == 1


async def test_a_camera_faster_than_the_track_is_paced_to_its_frame_rate_newest_first(
    stub: StubRosbridge,
) -> None:
    """A camera flooding the topic does not speed the video up: frames go out at ``fps``, their
    timestamps 1/fps apart, each with the newest picture there was."""
    flooding = True

    async def flood() -> None:
        number = 0
        while flooding:
            number += 1
            await stub.publish(TOPIC, jpeg_msg(number % 256))
            await asyncio.sleep(0.005)

    async with started(stub, fps=10) as camera:
        task = asyncio.create_task(flood())
        try:
            await eventually(lambda: camera.slot.received > 0, 5, "the first picture")
            begun = time.monotonic()
            frames = [await camera.recv() for _ in range(6)]
            elapsed = time.monotonic() - begun
            # Six frames at 10 fps: five periods of 0.1 s at least, however fast pictures came.
            assert elapsed >= 0.5 - 0.01
            periods = {b.pts - a.pts for a, b in itertools.pairwise(frames)}
            assert periods == {9000}  # 1/10 s at the video's 90 kHz clock
            assert camera.slot.received > camera.pictures  # pictures came faster than frames ...
            assert camera.slot.dropped >= 1  # ... and the older ones waiting were dropped
        finally:
            flooding = False
            await task


async def test_bad_frames_are_skipped_each_sort_said_once_and_the_next_good_one_shows(
    stub: StubRosbridge, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="vehicle_agent")
    async with started(stub) as camera:
        good = jpeg_msg(1)
        bad_text = json.dumps(
            {"op": "publish", "topic": TOPIC, "msg": {**as_json(good), "data": "@@not base64@@"}}
        )
        for _ in range(2):
            await stub.send(b"\x9f\x01\x02")  # CBOR that never ends
            await stub.send('{"op": "publish", ')  # JSON cut short
            await stub.send(bad_text)
            await eventually(lambda: camera.slot.received >= 1, 5, "the bad publication")
            await camera.recv()
            await stub.publish(TOPIC, {**good, "format": "tiff"})
            await eventually(lambda: camera.slot.received >= 2, 5, "the tiff")
            await camera.recv()
            await stub.publish(TOPIC, {**good, "data": good["data"][:2000]})
            await eventually(lambda: camera.slot.received >= 3, 5, "the truncated JPEG")
            await camera.recv()
            camera.slot.received = 0
        # Frames that are no rosbridge message are the connection's to count, not a topic's.
        assert camera.client.unreadable == 4
        assert camera.problems == {"message": 2, "format": 2, "corrupt": 2}
        skipped = [r.message for r in caplog.records if "skipped a" in r.message]
        assert len(skipped) == 4, skipped  # one line per sort
        assert any("not base64" in line for line in skipped)
        assert any("truncated or corrupt" in line for line in skipped)
        assert any("unreadable frame" in line for line in skipped)
        assert camera.pictures == 0
        await stub.publish(TOPIC, good)
        await eventually(lambda: camera.slot.received == 1, 5, "the good picture")
        assert pattern_error(rgb(await camera.recv())) <= 12


async def test_a_rosbridge_that_refuses_cbor_is_asked_again_for_json() -> None:
    async with (
        running(StubRosbridge(refuse_cbor=True)) as rosbridge,
        started(rosbridge) as camera,
    ):
        await eventually(lambda: len(rosbridge.subscribes) == 2, 5, "the second subscribe")
        assert [s.get("compression") for s in rosbridge.subscribes] == ["cbor", "none"]
        assert rosbridge.subscribes[1]["id"] == rosbridge.subscribes[0]["id"]
        await rosbridge.publish(TOPIC, jpeg_msg(2), binary=False)
        await eventually(lambda: camera.slot.received == 1, 5, "the JSON picture")
        assert pattern_error(rgb(await camera.recv())) <= 12
        assert camera.binary == 0


async def test_the_type_comes_from_rosapi_and_one_that_is_no_image_stops_the_start() -> None:
    async with running(StubRosbridge(topic_type="sensor_msgs/msg/Image")) as rosbridge:
        async with started(rosbridge) as camera:
            assert camera.message_type == "sensor_msgs/Image"
            assert rosbridge.subscribes[0]["type"] == "sensor_msgs/Image"
        rosbridge.topic_type = "std_msgs/msg/String"
        client = RosbridgeClient(rosbridge.url)
        try:
            with pytest.raises(CameraError, match="carries std_msgs/msg/String, not a camera"):
                await RosCamera(client, TOPIC).start()
        finally:
            await client.close()


async def test_without_rosapi_the_topics_name_decides() -> None:
    async with (
        running(StubRosbridge(topic_type="")) as rosbridge,
        started(rosbridge) as camera,
    ):
        assert camera.message_type == "sensor_msgs/CompressedImage"


async def test_an_unreachable_rosbridge_is_one_line_at_start() -> None:
    with pytest.raises(CameraError, match=f"camera {TOPIC}: cannot connect to rosbridge at"):
        await RosCamera(RosbridgeClient("ws://127.0.0.1:9"), TOPIC).start()
