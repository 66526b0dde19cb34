"""``--video ros:TOPIC`` against the server's own ``/rosbridge``: roslibpy (a real rosbridge
client, JSON with base64 data) publishes test pictures of both camera types and every encoding,
the agent's camera track subscribes in CBOR and in JSON, over the agent's own rosbridge client.

roslibpy's Twisted reactor starts once per process and stays running (see
tests/rosbridge/test_roslibpy.py), so the publishers here are module-scoped.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import roslibpy

from app.protocol import frametag, tokens
from app.protocol.events import FrameSent
from app.protocol.robot import PRESETS
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from tests.helpers.camera_frames import as_json, compressed, pattern, pattern_error, raw, read_back
from tests.helpers.sockets import rosbridge_url
from tests.helpers.waiting import eventually
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.events import EventLog
from vehicle_agent.robotlink import RosbridgeLink
from vehicle_agent.rosbridge_client import Compression, RosbridgeClient
from vehicle_agent.roscamera import RosCamera, camera_of

pytestmark = pytest.mark.timeout(120)

WAIT_S = 15.0
SECRET = "ros-camera-test-secret"
# Rows of the agent's own frame tag at 640 wide (its 16-pixel blocks): not the picture's.
TAG_ROWS = frametag.block_size(640)


@pytest.fixture(scope="module")
def server() -> Iterator[RunningServer]:
    running = start_in_thread(Settings(environment="development", token=None))
    yield running
    running.stop()


@pytest.fixture(scope="module")
def ros(server: RunningServer) -> Iterator[roslibpy.Ros]:
    client = roslibpy.Ros(host=rosbridge_url(server))
    client.run(timeout=WAIT_S)
    assert client.is_connected
    yield client
    client.close()


def advertise(ros: roslibpy.Ros, topic: str, kind: str) -> roslibpy.Topic:
    """Advertise ``topic`` and wait until the server's rosapi names its type: a camera that
    asked before the advertisement arrived would learn no type (or another's)."""
    publisher = roslibpy.Topic(ros, topic, kind)
    publisher.advertise()
    name = kind.rsplit("/", 1)[-1]
    deadline = time.monotonic() + WAIT_S
    while not str(ros.get_topic_type(topic)).endswith("/" + name):
        assert time.monotonic() < deadline, f"{topic} never advertised as {kind}"
        time.sleep(0.05)
    return publisher


def publish(publisher: roslibpy.Topic, msg: dict[str, Any]) -> None:
    publisher.publish(roslibpy.Message(as_json(msg)))


@contextlib.asynccontextmanager
async def camera(url: str, topic: str, token: str | None = None, **options: Any) -> Any:
    """A camera track on a rosbridge connection of its own (``token`` on its handshake)."""
    client = RosbridgeClient(url, token)
    track = RosCamera(client, topic, fps=100, **options)
    try:
        await track.start()
        yield track
    finally:
        track.stop()
        await client.close()


async def primed(publisher: roslibpy.Topic, msg: dict[str, Any], *tracks: RosCamera) -> None:
    """Publish ``msg`` until every track has had it. A track's subscription reaches the server
    on its own connection, so a publication sent at once may come before it and be missed (as
    on any rosbridge); after this, each publication reaches the tracks."""
    async with asyncio.timeout(WAIT_S):
        while not all(track.slot.received for track in tracks):
            publish(publisher, msg)
            await asyncio.sleep(0.05)


async def picture(track: RosCamera, received: int) -> np.ndarray:
    """The next frame once the track has had ``received`` messages."""
    await eventually(lambda: track.slot.received >= received, WAIT_S, f"message {received}")
    frame = await track.recv()
    return np.asarray(frame.to_ndarray(format="rgb24"))


CASES = {
    # name: (type, source size, make the message, largest pattern error allowed)
    "jpeg": ("sensor_msgs/CompressedImage", (320, 240), lambda p, t: compressed(p, "jpg", t), 12),
    "png": ("sensor_msgs/CompressedImage", (160, 120), lambda p, t: compressed(p, "png", t), 2),
    "rgb8": ("sensor_msgs/Image", (128, 96), lambda p, t: raw(p, "rgb8", t, padding=4), 2),
    "bgr8": ("sensor_msgs/Image", (128, 96), lambda p, t: raw(p, "bgr8", t), 2),
    "mono8": ("sensor_msgs/Image", (128, 96), lambda p, t: raw(p, "mono8", t, padding=2), 2),
}


@pytest.mark.parametrize("case", list(CASES))
async def test_each_type_and_encoding_arrives_as_sent_in_cbor_and_in_json_alike(
    server: RunningServer, ros: roslibpy.Ros, case: str
) -> None:
    kind, source, make, tolerance = CASES[case]
    topic = f"/camera/{case}"
    publisher = advertise(ros, topic, kind)
    sent: dict[Compression, list[FrameSent]] = {"cbor": [], "none": []}
    url = rosbridge_url(server)
    async with (
        camera(url, topic, compression="cbor", on_frame=sent["cbor"].append) as in_cbor,
        camera(url, topic, compression="none", on_frame=sent["none"].append) as in_json,
    ):
        assert in_cbor.message_type == in_json.message_type == kind  # from rosapi
        taken = time.time()
        await primed(publisher, make(pattern(*source, 4321), taken), in_cbor, in_json)
        frames = {"cbor": await picture(in_cbor, 1), "none": await picture(in_json, 1)}
        assert in_cbor.binary >= 1 and in_json.binary == 0
        for compression, frame in frames.items():
            number, back = read_back(frame, source)
            assert number == 4321, compression  # the picture's own number survived
            assert pattern_error(back, grey=case == "mono8") <= tolerance, compression
            assert frametag.read(frame) == 0  # the track's own number, above the picture
            (event,) = sent[compression]
            assert (event.frame, event.capture, event.face_x) == (0, "stamp", None)
            # The stamp moved onto this process's monotonic clock: taken before it arrived.
            assert 0 <= time.monotonic() - event.t < 5
        # CBOR and JSON brought the same bytes: the same pixels, to the last one.
        assert np.array_equal(frames["cbor"][TAG_ROWS:], frames["none"][TAG_ROWS:])
    publisher.unadvertise()


async def test_a_slow_consumer_gets_the_newest_picture_and_the_older_ones_are_dropped(
    server: RunningServer, ros: roslibpy.Ros
) -> None:
    topic = "/camera/latest"
    publisher = advertise(ros, topic, "sensor_msgs/CompressedImage")
    async with camera(rosbridge_url(server), topic) as track:
        await primed(publisher, numbered(0), track)
        await track.recv()
        received, dropped = track.slot.received, track.slot.dropped
        # The consumer takes nothing while five pictures come, one every 30 ms ...
        for number in range(1, 6):
            publish(publisher, numbered(number))
            await asyncio.sleep(0.03)
        await eventually(lambda: newest(track) == 5, WAIT_S, "picture 5 waiting")
        frame = np.asarray((await track.recv()).to_ndarray(format="rgb24"))
        # ... then gets the fifth, never the first: the others were dropped, undecoded.
        assert read_back(frame, (320, 240))[0] == 5
        assert track.slot.dropped - dropped == track.slot.received - received - 1 >= 1
        assert track.pictures == 2
        # Later pictures come on: again the newest wins.
        for number in (6, 7, 8):
            publish(publisher, numbered(number))
            await asyncio.sleep(0.03)
        await eventually(lambda: newest(track) == 8, WAIT_S, "picture 8 waiting")
        frame = np.asarray((await track.recv()).to_ndarray(format="rgb24"))
        assert read_back(frame, (320, 240))[0] == 8
        assert track.pictures == 3
    publisher.unadvertise()


def numbered(number: int) -> dict[str, Any]:
    """Picture ``number``, its number in its header's frame_id too (read before it is decoded)."""
    return compressed(pattern(320, 240, number), "jpg", time.time(), frame_id=f"n{number}")


def newest(track: RosCamera) -> int | None:
    """The number of the picture waiting in the track's slot (its header's frame_id), if any."""
    waiting = track.slot.waiting
    if waiting is None:
        return None
    return int(waiting.msg["header"]["frame_id"].removeprefix("n"))


# What the agent's log says of each sort of bad picture.
SAYS = {
    "encoding": "encoding 'yuv422' is not one the agent reads",
    "sizes": "data holds 36864 bytes, not height x step = 97 x 384",
    "truncated": "truncated or corrupt",
}


@pytest.mark.parametrize("problem", list(SAYS))
async def test_bad_pictures_through_the_server_are_skipped_and_the_next_good_one_shows(
    server: RunningServer, ros: roslibpy.Ros, problem: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="vehicle_agent.roscamera")
    topic = f"/camera/bad_{problem}"
    kind = "sensor_msgs/CompressedImage" if problem == "truncated" else "sensor_msgs/Image"
    publisher = advertise(ros, topic, kind)
    good = raw(pattern(128, 96, 77), "rgb8", time.time())
    first = raw(pattern(128, 96, 76), "rgb8", time.time())
    if problem == "encoding":
        bad = {**raw(pattern(128, 96, 1), "rgb8", time.time()), "encoding": "yuv422"}
    elif problem == "sizes":
        bad = {**good, "height": 97}  # data one row short of what it says
    else:
        jpeg = compressed(pattern(320, 240, 1), "jpg", time.time())
        bad = {**jpeg, "data": jpeg["data"][: len(jpeg["data"]) // 2]}
        good = compressed(pattern(320, 240, 77), "jpg", time.time())
        first = compressed(pattern(320, 240, 76), "jpg", time.time())
    async with camera(rosbridge_url(server), topic) as track:
        await primed(publisher, first, track)
        await track.recv()
        received = track.slot.received
        publish(publisher, bad)
        await picture(track, received + 1)
        assert sum(track.problems.values()) == 1 and track.pictures == 1
        (said,) = [r.message for r in caplog.records if "skipped a message" in r.message]
        assert said.startswith(f"camera {topic}: skipped a message: ") and SAYS[problem] in said
        publish(publisher, good)
        frame = await picture(track, received + 2)
        source = (128, 96) if problem != "truncated" else (320, 240)
        assert read_back(frame, source)[0] == 77
    publisher.unadvertise()


# -- with tokens -----------------------------------------------------------------------------------


@pytest.fixture
def guarded(start_server: Callable[[Settings], RunningServer]) -> RunningServer:
    return start_server(Settings(environment="development", secret=SECRET))


def token(role: tokens.Role, room: str = "lab", ttl_s: float = 600) -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=ttl_s)


def authenticated_ros(server: RunningServer, bearer: str) -> roslibpy.Ros:
    client = roslibpy.Ros(host=rosbridge_url(server), headers={"Authorization": f"Bearer {bearer}"})
    client.run(timeout=WAIT_S)
    assert client.is_connected
    return client


async def test_a_vehicle_publishes_its_camera_for_its_own_room_only(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    # Rooms of their own: the diffdrive server's, one robot (and one hub) a room.
    rooms = start_server(Settings(environment="development", secret=SECRET, robot="diffdrive"))
    topic = "/rover/camera/compressed"
    vehicle = authenticated_ros(rooms, token("vehicle"))
    try:
        publisher = advertise(vehicle, topic, "sensor_msgs/CompressedImage")
        url = rosbridge_url(rooms)
        async with (
            camera(url, topic, token=token("client")) as watcher,
            camera(url, topic, token=token("vehicle", room="elsewhere")) as stranger,
        ):
            await primed(publisher, compressed(pattern(320, 240, 9), "jpg", time.time()), watcher)
            frame = await picture(watcher, 1)
            assert read_back(frame, (320, 240))[0] == 9
            await asyncio.sleep(0.5)
            # Another room's token reached a topic of its own name, on which nothing came.
            assert stranger.slot.received == 0
    finally:
        vehicle.close()


@pytest.mark.slow
async def test_the_cameras_connection_outlives_its_token_by_renewing_with_the_agent(
    guarded: RunningServer,
) -> None:
    """The server's /rosbridge ends a session whose token expires unless it proves a fresh one:
    the camera shares the robot link's connection, which proves each token the agent renews."""
    lifetime = 6.0
    first = token("vehicle", room="default", ttl_s=lifetime)
    topic = "/camera/renewed"
    vehicle = authenticated_ros(guarded, token("vehicle", room="default"))
    publisher = advertise(vehicle, topic, "sensor_msgs/CompressedImage")
    client = RosbridgeClient(rosbridge_url(guarded), first)
    track = RosCamera(client, topic, fps=15)
    await track.start()
    link = RosbridgeLink(client)
    agent = Agent(AgentConfig(server=guarded.url, token=first), track, link, EventLog())
    task = asyncio.create_task(agent.run())
    try:
        await asyncio.sleep(2.5 * lifetime)
        before = track.slot.received
        publish(publisher, compressed(pattern(320, 240, 3), "jpg", time.time()))
        await eventually(lambda: track.slot.received > before, WAIT_S, "a picture after expiry")
        assert agent.token != first
        # One connection carried both, and never had to open again.
        assert client.connected and client.opened == 1
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        vehicle.close()


async def test_a_message_not_of_the_topics_type_never_leaves_the_server(
    server: RunningServer, ros: roslibpy.Ros
) -> None:
    """The server checks each image against its topic's type (the publisher is told why, when
    it listens for statuses): the agent never sees it, and the next good one comes on."""
    topic = "/camera/checked"
    publisher = advertise(ros, topic, "sensor_msgs/msg/Image")
    good = raw(pattern(128, 96, 55), "rgb8", time.time())
    async with camera(rosbridge_url(server), topic) as track:
        await primed(publisher, raw(pattern(128, 96, 54), "rgb8", time.time()), track)
        await track.recv()
        received = track.slot.received
        sent = as_json(good)
        for bad in ({"height": "ninety-six"}, {"data": "@@ not base64 @@"}, {"colour": "red"}):
            publisher.publish(roslibpy.Message({**sent, **bad}))
        publish(publisher, good)
        frame = await picture(track, received + 1)
        assert read_back(frame, (128, 96))[0] == 55
        await asyncio.sleep(0.3)
        assert (track.slot.received - received, sum(track.problems.values())) == (1, 0)
    publisher.unadvertise()


@pytest.mark.parametrize("compression", ["cbor", "none"])
async def test_the_diffdrive_robots_own_camera_is_what_video_ros_takes(
    start_server: Callable[[Settings], RunningServer], compression: Compression
) -> None:
    """``--video ros --robot diffdrive`` against the server that simulates that robot: the
    description's camera topic, the type rosapi names, its rendered pictures decoded."""
    rooms = start_server(Settings(environment="development", token=None, robot="diffdrive"))
    topic, described = camera_of("ros", PRESETS["diffdrive"])
    async with camera(
        rosbridge_url(rooms), topic, described=described, compression=compression
    ) as track:
        assert track.message_type == "sensor_msgs/CompressedImage"
        await eventually(lambda: track.slot.received >= 1, WAIT_S, "the robot's camera")
        frame = await track.recv()
        assert (frame.width, frame.height) == (640, 480)
        assert track.pictures == 1 and not track.problems
        assert (track.binary > 0) == (compression == "cbor")
