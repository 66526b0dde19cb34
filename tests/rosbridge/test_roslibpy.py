"""``/rosbridge`` on the real app, driven by the third-party client roslibpy and by raw sockets.

roslibpy runs Twisted's reactor in a daemon thread that can be started only once per process,
so one module-scoped client serves every roslibpy test here, and the reactor is left running
(stopping it would break any later roslibpy user in the same pytest run). Status messages come
only after ``set_level`` (roslibpy never sends it, and logs them as unhandled), so the error cases
use a raw ``websockets`` client that asks for them.
"""

from __future__ import annotations

import asyncio
import json
import queue
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import httpx
import pytest
import roslibpy
import websockets

from app.protocol.rooms import DEFAULT_ROOM
from app.server.config import Settings
from app.server.rosbridge import Simulator
from app.server.serve import RunningServer, start_in_thread
from app.turtlesim.sim import TurtleSim
from tests.helpers.sockets import rosbridge_url
from tests.helpers.waiting import wait_until

pytestmark = pytest.mark.timeout(120)

# Generous: the machine is shared and loaded; waits end as soon as their condition holds.
WAIT_S = 15.0
CENTRE = TurtleSim.WORLD_SIZE / 2


@pytest.fixture(scope="module")
def server() -> Iterator[RunningServer]:
    running = start_in_thread(Settings(environment="development", token=None))
    yield running
    running.stop()


@pytest.fixture(name="rosbridge_url", scope="module")
def rosbridge_url_fixture(server: RunningServer) -> str:
    return rosbridge_url(server)


@pytest.fixture(scope="module")
def ros(rosbridge_url: str) -> Iterator[roslibpy.Ros]:
    # With no port, roslibpy takes ``host`` as the whole URL, path included.
    client = roslibpy.Ros(host=rosbridge_url)
    client.run(timeout=WAIT_S)
    assert client.is_connected
    yield client
    client.close()


@pytest.fixture
def simulator(server: RunningServer) -> Simulator:
    app: Any = server.server.config.app
    sim: Simulator = app.state.simulator
    return sim


@pytest.fixture(autouse=True)
def fresh_world(ros: roslibpy.Ros) -> None:
    """Every test starts from one turtle1 at the centre, as after ``rosservice call /reset``."""
    roslibpy.Service(ros, "/reset", "std_srvs/Empty").call(
        roslibpy.ServiceRequest({}), timeout=WAIT_S
    )


def state(server: RunningServer) -> dict[str, Any]:
    response = httpx.get(server.url + "/turtlesim/state", timeout=WAIT_S)
    response.raise_for_status()
    result: dict[str, Any] = response.json()
    return result


def turtle(server: RunningServer, name: str) -> dict[str, Any]:
    (found,) = [t for t in state(server)["turtles"] if t["name"] == name]
    return found


class Poses:
    """Pose messages received by a roslibpy subscription."""

    def __init__(self) -> None:
        self.received: queue.Queue[dict[str, Any]] = queue.Queue()

    def __call__(self, message: dict[str, Any]) -> None:
        self.received.put(message)

    def next(self) -> dict[str, Any]:
        return self.received.get(timeout=WAIT_S)

    def until(self, condition: Callable[[dict[str, Any]], bool], what: str) -> dict[str, Any]:
        deadline = time.monotonic() + WAIT_S
        while time.monotonic() < deadline:
            pose = self.next()
            if condition(pose):
                return pose
        raise AssertionError(f"no pose with {what} within {WAIT_S} s")


# -- roslibpy ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("twist_type", "pose_type"),
    [("geometry_msgs/Twist", "turtlesim/Pose"), ("geometry_msgs/msg/Twist", "turtlesim/msg/Pose")],
)
def test_publish_cmd_vel_and_watch_the_pose_change(
    ros: roslibpy.Ros, twist_type: str, pose_type: str
) -> None:
    poses = Poses()
    pose_topic = roslibpy.Topic(ros, "/turtle1/pose", pose_type)
    cmd_vel = roslibpy.Topic(ros, "/turtle1/cmd_vel", twist_type)
    pose_topic.subscribe(poses)
    try:
        start = poses.next()
        assert (start["x"], start["y"], start["theta"]) == pytest.approx((CENTRE, CENTRE, 0.0))
        cmd_vel.publish(
            roslibpy.Message({"linear": {"x": 1.0, "y": 0, "z": 0}, "angular": {"z": 1.0}})
        )
        moving = poses.until(lambda p: p["theta"] > 0.1, "theta > 0.1")
        assert moving["linear_velocity"] == 1.0
        assert moving["angular_velocity"] == 1.0
        # The turtle drives a left-hand arc: forward and to the left of where it started.
        assert moving["x"] > CENTRE
        assert moving["y"] > CENTRE
        # turtlesim stops one second after the last command.
        stopped = poses.until(lambda p: p["angular_velocity"] == 0.0, "the command expired")
        assert stopped["theta"] == pytest.approx(1.0, abs=0.25)
    finally:
        pose_topic.unsubscribe()
        cmd_vel.unadvertise()


def test_throttled_subscription(ros: roslibpy.Ros) -> None:
    poses = Poses()
    topic = roslibpy.Topic(ros, "/turtle1/pose", "turtlesim/Pose", throttle_rate=200)
    topic.subscribe(poses)
    try:
        first = time.monotonic()
        poses.next()
        for _ in range(5):
            poses.next()
        elapsed = time.monotonic() - first
        # Five gaps of at least 200 ms at the server (every-tick delivery would take about
        # 80 ms); arrival jitter on a loaded machine can shorten what the client sees a little.
        assert elapsed > 0.6
    finally:
        topic.unsubscribe()


def test_spawn_and_teleport_through_services(ros: roslibpy.Ros, server: RunningServer) -> None:
    spawn = roslibpy.Service(ros, "/spawn", "turtlesim/Spawn")
    response = spawn.call(
        roslibpy.ServiceRequest({"x": 2.0, "y": 3.0, "theta": 0.0, "name": ""}), timeout=WAIT_S
    )
    assert response["name"] == "turtle2"
    teleport = roslibpy.Service(ros, "/turtle1/teleport_absolute", "turtlesim/TeleportAbsolute")
    teleport.call(roslibpy.ServiceRequest({"x": 1.0, "y": 9.0, "theta": 1.5}), timeout=WAIT_S)
    # As in turtlesim, the teleport is queued and happens on the next tick.
    wait_until(lambda: turtle(server, "turtle1")["x"] == pytest.approx(1.0), WAIT_S, "the teleport")
    turtles = {t["name"]: t for t in state(server)["turtles"]}
    assert sorted(turtles) == ["turtle1", "turtle2"]
    assert (turtles["turtle2"]["x"], turtles["turtle2"]["y"]) == pytest.approx((2.0, 3.0))
    one = turtles["turtle1"]
    assert (one["x"], one["y"], one["theta"]) == pytest.approx((1.0, 9.0, 1.5))
    # The jump was drawn with turtle1's pen.
    strokes = [s for s in state(server)["strokes"] if s["turtle"] == "turtle1"]
    assert strokes[-1]["points"][-1] == pytest.approx([1.0, 9.0])


def test_a_failing_service_call_raises_in_roslibpy(ros: roslibpy.Ros) -> None:
    kill = roslibpy.Service(ros, "/kill", "turtlesim/Kill")
    with pytest.raises(roslibpy.core.ServiceException, match="turtle9"):
        kill.call(roslibpy.ServiceRequest({"name": "turtle9"}), timeout=WAIT_S)
    # The connection keeps serving.
    spawn = roslibpy.Service(ros, "/spawn", "turtlesim/srv/Spawn")
    assert spawn.call(roslibpy.ServiceRequest({"name": "leo"}), timeout=WAIT_S)["name"] == "leo"


def test_discovery_through_rosapi(ros: roslibpy.Ros) -> None:
    roslibpy.Service(ros, "/spawn", "turtlesim/Spawn").call(
        roslibpy.ServiceRequest({"name": "leo"}), timeout=WAIT_S
    )
    # The real graph of a ROS 2 turtlesim robot: each turtle's three topics, /rosout and
    # /parameter_events (this listed only cmd_vel and pose before the graph was modelled).
    assert set(ros.get_topics()) == {
        "/turtle1/cmd_vel",
        "/turtle1/color_sensor",
        "/turtle1/pose",
        "/leo/cmd_vel",
        "/leo/color_sensor",
        "/leo/pose",
        "/parameter_events",
        "/rosout",
    }
    assert "/leo/teleport_absolute" in ros.get_services()
    assert ros.get_topic_type("/leo/pose") == "turtlesim/msg/Pose"


# -- raw sockets: errors, many clients, cleanup ---------------------------------------------------


async def exchange(url: str, *frames: str | bytes, replies: int) -> list[dict[str, Any]]:
    """Send frames on a fresh connection and collect the first ``replies`` messages."""
    async with websockets.connect(url) as ws:
        for frame in frames:
            await ws.send(frame)
        return [json.loads(await asyncio.wait_for(ws.recv(), WAIT_S)) for _ in range(replies)]


async def test_bad_ops_get_status_errors_naming_the_problem(rosbridge_url: str) -> None:
    frames = [
        json.dumps({"op": "set_level", "level": "error"}),  # statuses only for who asks
        "{broken",
        json.dumps({"op": "fly", "id": "e1"}),
        json.dumps({"op": "subscribe", "id": "e2"}),
        json.dumps({"op": "publish", "id": "e3", "topic": "/turtle9/cmd_vel", "msg": {}}),
        json.dumps({"op": "subscribe", "id": "e4", "topic": "/chatter", "type": "std_msgs/String"}),
        json.dumps(
            {"op": "publish", "id": "e5", "topic": "/turtle1/cmd_vel", "msg": {"velocity": 1}}
        ),
        b"\x00\x01",
    ]
    errors = await exchange(rosbridge_url, *frames, replies=len(frames) - 1)
    assert all(e["op"] == "status" and e["level"] == "error" for e in errors)
    assert [e.get("id") for e in errors] == [None, "e1", "e2", "e3", "e4", "e5", None]
    words = [
        "malformed JSON",
        "fly",
        "topic",
        "turtle9",
        "unknown topic",
        "velocity",
        "binary",
    ]
    for error, word in zip(errors, words, strict=True):
        assert word in error["msg"]


async def test_unknown_service_gets_a_failed_response_and_no_status(rosbridge_url: str) -> None:
    # As current rosbridge_suite: only the service_response, however long we listen.
    call = json.dumps({"op": "call_service", "id": "c1", "service": "/nowhere"})
    async with websockets.connect(rosbridge_url) as ws:
        await ws.send(call)
        response = json.loads(await asyncio.wait_for(ws.recv(), WAIT_S))
        assert (response["op"], response["result"], response["id"]) == (
            "service_response",
            False,
            "c1",
        )
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(ws.recv(), 0.5)


async def test_unknown_service_gets_status_and_failed_response_after_set_level(
    rosbridge_url: str,
) -> None:
    set_level = json.dumps({"op": "set_level", "level": "error"})
    call = json.dumps({"op": "call_service", "id": "c1", "service": "/nowhere"})
    status, response = await exchange(rosbridge_url, set_level, call, replies=2)
    assert status["op"] == "status"
    assert status["id"] == "c1"
    assert response["op"] == "service_response"
    assert response["result"] is False
    assert response["id"] == "c1"


async def test_many_clients_at_once_each_get_their_poses(rosbridge_url: str) -> None:
    subscribe = json.dumps({"op": "subscribe", "topic": "/turtle1/pose"})

    async def client() -> list[dict[str, Any]]:
        return await exchange(rosbridge_url, subscribe, replies=3)

    results = await asyncio.gather(*(client() for _ in range(12)))
    for messages in results:
        assert [m["topic"] for m in messages] == ["/turtle1/pose"] * 3


async def test_closed_sockets_leave_no_sessions_behind(
    rosbridge_url: str, simulator: Simulator
) -> None:
    before = len(simulator.hub_for(DEFAULT_ROOM).sessions)
    subscribe = json.dumps({"op": "subscribe", "topic": "/turtle1/pose"})
    async with websockets.connect(rosbridge_url) as ws:
        await ws.send(subscribe)
        await asyncio.wait_for(ws.recv(), WAIT_S)
        assert len(simulator.hub_for(DEFAULT_ROOM).sessions) == before + 1
    deadline = time.monotonic() + WAIT_S
    while len(simulator.hub_for(DEFAULT_ROOM).sessions) != before:
        assert time.monotonic() < deadline, "session still registered after its socket closed"
        await asyncio.sleep(0.01)


def test_simulator_ticks_at_about_62_hz(server: RunningServer) -> None:
    first = state(server)["tick"]
    started = time.monotonic()
    threading.Event().wait(1.0)
    ticks = state(server)["tick"] - first
    elapsed = time.monotonic() - started
    # 16 ms of wall time per tick; allow for a loaded machine in both directions.
    assert 0.6 * elapsed / 0.016 < ticks < 1.5 * elapsed / 0.016


# -- rosapi through roslibpy's helpers, one server per ROS flavour ----------------------------

POSE_TYPE = {"1": "turtlesim/Pose", "2": "turtlesim/msg/Pose", "jazzy": "turtlesim_msgs/msg/Pose"}


@pytest.fixture(scope="module", params=["1", "2", "jazzy"])
def flavoured(request: pytest.FixtureRequest) -> Iterator[tuple[str, roslibpy.Ros]]:
    """A server started with ``ros=<flavour>`` and a roslibpy client on it."""
    flavour: str = request.param
    running = start_in_thread(Settings(environment="development", token=None, ros=flavour))
    client = roslibpy.Ros(host=running.url.replace("http", "ws", 1) + "/rosbridge")
    client.run(timeout=WAIT_S)
    yield flavour, client
    client.close()
    running.stop()


def test_roslibpy_rosapi_helpers(flavoured: tuple[str, roslibpy.Ros]) -> None:
    flavour, ros = flavoured
    assert "/rosout" in ros.get_topics()
    assert ros.get_topic_type("/turtle1/pose") == POSE_TYPE[flavour]
    assert "/turtle1/teleport_relative" in ros.get_services()
    spawn_type = ros.get_service_type("/spawn")
    assert spawn_type == POSE_TYPE[flavour].replace("msg/", "srv/").replace("Pose", "Spawn")
    assert "/turtlesim" in ros.get_nodes()
    details = ros.get_node_details("/turtlesim")
    assert "/turtle1/pose" in details["publishing"]
    assert "/turtle1/cmd_vel" in details["subscribing"]
    sep = "/" if flavour == "1" else ":"
    names = ros.get_params()
    assert {f"/turtlesim{sep}background_{c}" for c in "rgb"} <= set(names)
    assert ros.get_param(f"/turtlesim{sep}background_b") == 255
    roslibpy.Param(ros, f"/turtlesim{sep}background_r").set(12, timeout=WAIT_S)
    assert ros.get_param(f"/turtlesim{sep}background_r") == 12


def test_get_time_in_the_flavours_shape(flavoured: tuple[str, roslibpy.Ros]) -> None:
    flavour, ros = flavoured
    before = time.time()
    if flavour == "1":
        # roslibpy's get_time reads ROS 1's {secs, nsecs}.
        stamp = ros.get_time()
        assert stamp.secs >= int(before)
        return
    # ROS 2 rosapi answers {sec, nanosec}, which roslibpy 2.1's get_time does not read.
    reply = roslibpy.Service(ros, "/rosapi/get_time", "rosapi_msgs/srv/GetTime").call(
        roslibpy.ServiceRequest({}), timeout=WAIT_S
    )
    assert set(reply["time"]) == {"sec", "nanosec"}
    assert reply["time"]["sec"] >= int(before)


def test_topics_and_raw_types_for_foxglove(flavoured: tuple[str, roslibpy.Ros]) -> None:
    flavour, ros = flavoured
    reply = roslibpy.Service(ros, "/rosapi/topics_and_raw_types", "rosapi/TopicsAndRawTypes").call(
        roslibpy.ServiceRequest({}), timeout=WAIT_S
    )
    texts = dict(zip(reply["topics"], reply["typedefs_full_text"], strict=True))
    types = dict(zip(reply["topics"], reply["types"], strict=True))
    assert types["/turtle1/pose"] == POSE_TYPE[flavour]
    assert "float32 theta" in texts["/turtle1/pose"]
