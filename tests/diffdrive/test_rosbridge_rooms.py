"""The diffdrive robots through the server's real ``/rosbridge``, with roslibpy: one robot per
room, each room's tokens reaching only its own, and the camera's JPEG frames flowing.

roslibpy runs Twisted's reactor in a daemon thread that is started once per process and left
running (see tests/rosbridge/test_roslibpy.py); every client here shares it.
"""

from __future__ import annotations

import asyncio
import base64
import json
import queue
import time
from collections.abc import Callable, Iterator
from typing import Any

import cv2
import httpx
import numpy as np
import pytest
import roslibpy
import websockets

from app.diffdrive.arena import ARENA
from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from tests.helpers.sockets import rosbridge_url

pytestmark = pytest.mark.timeout(120)

SECRET = "diffdrive-rooms-test-secret-0123456789abcdef"
# Generous: the machine is shared and loaded; waits end as soon as their condition holds.
WAIT_S = 15.0


@pytest.fixture(scope="module")
def guarded() -> Iterator[RunningServer]:
    """A diffdrive server with access control: every connection proves a room's token."""
    running = start_in_thread(Settings(environment="development", robot="diffdrive", secret=SECRET))
    yield running
    running.stop()


@pytest.fixture(scope="module")
def open_server() -> Iterator[RunningServer]:
    """A diffdrive server without access control: a connection names its room in its URL."""
    running = start_in_thread(Settings(environment="development", robot="diffdrive"))
    yield running
    running.stop()


def token(room: str, role: tokens.Role) -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=600)


def connect(url: str, headers: dict[str, str] | None = None) -> roslibpy.Ros:
    # With no port, roslibpy takes ``host`` as the whole URL, path and query included.
    client = roslibpy.Ros(host=url, headers=headers)
    client.run(timeout=WAIT_S)
    assert client.is_connected
    return client


def with_token(server: RunningServer, room: str, role: tokens.Role) -> roslibpy.Ros:
    return connect(rosbridge_url(server), {"Authorization": f"Bearer {token(room, role)}"})


class Latest:
    """The messages of one roslibpy subscription."""

    def __init__(self, ros: roslibpy.Ros, topic: str, kind: str) -> None:
        self.received: queue.Queue[dict[str, Any]] = queue.Queue()
        self.topic = roslibpy.Topic(ros, topic, kind)
        self.topic.subscribe(self.received.put)

    def next(self) -> dict[str, Any]:
        return self.received.get(timeout=WAIT_S)

    def latest(self) -> dict[str, Any]:
        """The newest message: what came before it is dropped (a new one is waited for)."""
        while not self.received.empty():
            self.received.get_nowait()
        return self.next()

    def until(self, condition: Callable[[dict[str, Any]], bool], what: str) -> dict[str, Any]:
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            message = self.next()
            if condition(message):
                return message
        raise AssertionError(f"no message with {what} within {WAIT_S} s")


def x_of(odom: dict[str, Any]) -> float:
    return float(odom["pose"]["pose"]["position"]["x"])


def drive(ros: roslibpy.Ros, linear: float) -> roslibpy.Topic:
    cmd_vel = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/Twist")
    cmd_vel.publish(roslibpy.Message({"linear": {"x": linear}, "angular": {"z": 0.0}}))
    return cmd_vel


def test_a_rooms_vehicle_token_drives_its_own_robot_and_no_other(guarded: RunningServer) -> None:
    vehicle_a = with_token(guarded, "diff-a", "vehicle")
    watcher_b = with_token(guarded, "diff-b", "client")
    try:
        odom_a = Latest(vehicle_a, "/odom", "nav_msgs/Odometry")
        odom_b = Latest(watcher_b, "/odom", "nav_msgs/Odometry")
        start_a, start_b = x_of(odom_a.next()), x_of(odom_b.next())
        assert start_a == start_b == ARENA.start.x  # two robots, each at its room's start
        for _ in range(10):  # within the 1 s timeout, for about a second
            drive(vehicle_a, 0.5)
            time.sleep(0.1)
        moved = odom_a.until(lambda m: x_of(m) > start_a + 0.2, "room A's robot moved")
        # Room B's robot stood still all along, whatever room A's vehicle published.
        assert x_of(odom_b.latest()) == start_b
        assert x_of(moved) > start_b + 0.2
    finally:
        vehicle_a.close()
        watcher_b.close()


def test_a_client_token_reads_its_room_but_cannot_drive(guarded: RunningServer) -> None:
    client = with_token(guarded, "diff-c", "client")
    try:
        odom = Latest(client, "/odom", "nav_msgs/Odometry")
        start = x_of(odom.next())
        for _ in range(5):
            drive(client, 0.5)
            time.sleep(0.1)
        time.sleep(0.3)
        assert x_of(odom.latest()) == start
    finally:
        client.close()


def test_a_connection_bound_to_a_room_cannot_be_renewed_into_another(
    guarded: RunningServer,
) -> None:
    """A client token of room D, then a vehicle token of room E sent as a renewal: refused,
    and the connection still only reads room D's robot."""

    async def attempt() -> list[dict[str, Any]]:
        url = rosbridge_url(guarded)
        headers = {"Authorization": f"Bearer {token('diff-d', 'client')}"}
        async with websockets.connect(url, additional_headers=headers) as ws:
            await ws.send(json.dumps({"op": "set_level", "level": "error"}))
            await ws.send(json.dumps({"op": "auth", "token": token("diff-e", "vehicle"), "id": 1}))
            await ws.send(
                json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": {"linear": {"x": 1}}})
            )
            replies = []
            for _ in range(2):
                replies.append(json.loads(await asyncio.wait_for(ws.recv(), WAIT_S)))
            return replies

    renewal, publish = asyncio.run(attempt())
    assert renewal["id"] == 1 and "room 'diff-d'" in renewal["msg"]
    assert "needs a vehicle token" in publish["msg"]


def test_without_tokens_each_room_named_in_the_url_has_its_own_robot(
    open_server: RunningServer,
) -> None:
    base = rosbridge_url(open_server)
    room_f, room_g = connect(f"{base}?room=diff-f"), connect(f"{base}?room=diff-g")
    try:
        odom_f = Latest(room_f, "/odom", "nav_msgs/Odometry")
        odom_g = Latest(room_g, "/odom", "nav_msgs/Odometry")
        start = x_of(odom_g.next())
        for _ in range(8):
            drive(room_f, 0.5)
            time.sleep(0.1)
        odom_f.until(lambda m: x_of(m) > start + 0.2, "room F's robot moved")
        assert x_of(odom_g.latest()) == start
    finally:
        room_f.close()
        room_g.close()


def test_a_url_that_names_no_room_is_refused(open_server: RunningServer) -> None:
    async def attempt() -> None:
        async with websockets.connect(rosbridge_url(open_server) + "?room="):
            pass

    with pytest.raises(websockets.InvalidStatus):
        asyncio.run(attempt())


def test_the_camera_delivers_jpeg_frames_of_the_room_at_its_rate(
    open_server: RunningServer,
) -> None:
    """A correctness check that frames flow at about the camera's 30 a second: at least a
    third of that over two seconds on a loaded machine, each a 640x480 JPEG."""
    ros = connect(rosbridge_url(open_server) + "?room=diff-camera")
    try:
        frames = Latest(ros, "/camera/image/compressed", "sensor_msgs/CompressedImage")
        first = frames.next()
        started = time.monotonic()
        count = 0
        while time.monotonic() - started < 2.0:
            try:
                frames.received.get(timeout=0.5)
                count += 1
            except queue.Empty:
                pass
        assert count >= 20, f"{count} frames in 2 s"
        assert first["format"] == "jpeg"
        image = cv2.imdecode(np.frombuffer(base64.b64decode(first["data"]), np.uint8), 1)
        assert image.shape == (480, 640, 3)
        assert float(image.std()) > 15  # a room, not a blank frame
    finally:
        ros.close()


def test_a_room_beyond_the_limit_is_told_to_come_back_and_gets_a_robot_once_one_is_free() -> None:
    """With room for one robot: a second room's connection is refused with a status error and
    close 1013 (try again later) while the first room is connected, and served once it left."""
    running = start_in_thread(Settings(environment="development", robot="diffdrive"))
    running.server.config.app.state.simulator.max_rooms = 1
    base = rosbridge_url(running)
    subscribe = json.dumps({"op": "subscribe", "topic": "/odom", "throttle_rate": 100})

    async def attempt() -> tuple[dict[str, Any], int | None, dict[str, Any]]:
        async with websockets.connect(f"{base}?room=first") as first:
            await first.send(subscribe)
            await asyncio.wait_for(first.recv(), WAIT_S)  # the first room's robot runs
            async with websockets.connect(f"{base}?room=second") as second:
                refusal = json.loads(await asyncio.wait_for(second.recv(), WAIT_S))
                with pytest.raises(websockets.ConnectionClosed):
                    await asyncio.wait_for(second.recv(), WAIT_S)
                code = second.close_code
        # The server forgets the first connection a moment after it closed: until then the
        # second room is still refused.
        deadline = time.monotonic() + WAIT_S
        while True:
            try:
                async with websockets.connect(f"{base}?room=second") as second:
                    await second.send(subscribe)
                    reply = json.loads(await asyncio.wait_for(second.recv(), WAIT_S))
            except websockets.ConnectionClosed:  # refused again, before it read the reason
                reply = {"op": "closed"}
            if reply["op"] == "publish" or time.monotonic() > deadline:
                return refusal, code, reply
            await asyncio.sleep(0.1)

    try:
        refusal, code, odom = asyncio.run(attempt())
    finally:
        running.stop()
    assert refusal["op"] == "status" and "at most 1 rooms" in refusal["msg"]
    assert code == 1013
    assert odom["op"] == "publish", f"the second room is still refused: {odom}"
    assert odom["topic"] == "/odom" and x_of(odom["msg"]) == ARENA.start.x


def test_the_room_state_gives_the_billboards_of_the_tokens_room(guarded: RunningServer) -> None:
    headers = {"Authorization": f"Bearer {token('diff-h', 'client')}"}
    reply = httpx.get(guarded.url + "/arena/state", headers=headers, timeout=WAIT_S)
    assert reply.status_code == 200
    names = {b["name"] for b in reply.json()["billboards"]}
    assert names == {b.name for b in ARENA.billboards}
    other = httpx.get(guarded.url + "/arena/state?room=diff-i", headers=headers, timeout=WAIT_S)
    assert other.status_code == 403
    assert httpx.get(guarded.url + "/arena/state", timeout=WAIT_S).status_code == 401
