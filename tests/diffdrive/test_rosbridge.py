"""The diffdrive robot over the rosbridge protocol, without sockets: /cmd_vel, /odom, the
camera topic, the type names of each ROS flavour and rosapi's answers."""

from __future__ import annotations

import base64
import json
import math
from typing import Any

import pytest

from app.diffdrive.robot import DiffDrive
from app.diffdrive.rosbridge import DiffDriveHub
from app.diffdrive.sim import ArenaSim
from app.protocol.ros import RosFlavour
from app.rosbridge.protocol import RosbridgeSession

Json = dict[str, Any]
ODOMETRY = {
    "1": "nav_msgs/Odometry",
    "2": "nav_msgs/msg/Odometry",
    "jazzy": "nav_msgs/msg/Odometry",
}
IMAGE = {
    "1": "sensor_msgs/CompressedImage",
    "2": "sensor_msgs/msg/CompressedImage",
    "jazzy": "sensor_msgs/msg/CompressedImage",
}
TWIST = {
    "1": "geometry_msgs/Twist",
    "2": "geometry_msgs/msg/Twist",
    "jazzy": "geometry_msgs/msg/Twist",
}


class Arena:
    """An arena's hub whose clock the test moves, one 16 ms tick at a time."""

    def __init__(self, flavour: RosFlavour = "2") -> None:
        self.now = 10.0
        self.sim = ArenaSim(clock=lambda: self.now)
        self.hub = DiffDriveHub(self.sim, flavour, wall_clock=lambda: 1_700_000_000.0 + self.now)

    def tick(self, count: int = 1) -> None:
        for _ in range(count):
            self.now += DiffDrive.TICK_S
            self.sim.step()
            self.hub.tick(self.now)

    def session(self) -> RosbridgeSession:
        session = self.hub.open_session()
        session.receive(json.dumps({"op": "set_level", "level": "info"}))
        return session


def send(session: RosbridgeSession, **message: Any) -> list[Json]:
    return session.receive(json.dumps(message))


def published(session: RosbridgeSession, topic: str) -> list[Json]:
    return [m["msg"] for m in session.take_publications() if m["topic"] == topic]


def call(session: RosbridgeSession, service: str, **args: Any) -> Json:
    replies = send(session, op="call_service", service=service, args=args, id="c")
    return [r for r in replies if r["op"] == "service_response"][0]


def test_a_twist_on_cmd_vel_drives_the_robot_and_odom_follows_it() -> None:
    arena = Arena()
    session = arena.session()
    assert send(session, op="subscribe", topic="/odom") == []
    start = arena.sim.robot.state()
    assert send(session, op="publish", topic="/cmd_vel", msg={"linear": {"x": 0.5}}) == []
    arena.tick(50)
    [odom] = published(session, "/odom")  # only the latest: a newer pose supersedes
    position = odom["pose"]["pose"]["position"]
    assert position["x"] == pytest.approx(start.x + 0.5 * 50 * DiffDrive.TICK_S)
    assert position["y"] == pytest.approx(start.y)
    assert odom["twist"]["twist"]["linear"]["x"] == 0.5
    assert odom["header"]["frame_id"] == "odom"


def test_odom_carries_the_heading_as_a_quaternion() -> None:
    arena = Arena()
    session = arena.session()
    send(session, op="subscribe", topic="odom")  # the leading slash is optional
    send(session, op="publish", topic="cmd_vel", msg={"angular": {"z": 1.0}})
    arena.tick(50)
    [odom] = published(session, "odom")
    q = odom["pose"]["pose"]["orientation"]
    yaw = math.atan2(2 * q["w"] * q["z"], 1 - 2 * q["z"] ** 2)
    assert yaw == pytest.approx(50 * DiffDrive.TICK_S)
    assert odom["header"]["stamp"]["sec"] == 1_700_000_010


def test_every_tick_is_a_new_odometry_message() -> None:
    arena = Arena()
    session = arena.session()
    send(session, op="subscribe", topic="/odom")
    seqs = []
    for _ in range(3):
        arena.tick()
        [odom] = published(session, "/odom")
        seqs.append(odom["header"]["stamp"]["nanosec"])
    assert len(set(seqs)) == 3
    assert published(session, "/odom") == []  # nothing new without a tick


@pytest.mark.parametrize("flavour", ["1", "2", "jazzy"])
def test_each_flavour_names_the_types_its_way(flavour: RosFlavour) -> None:
    arena = Arena(flavour)
    session = arena.session()
    for topic, kind in (
        ("/odom", ODOMETRY[flavour]),
        ("/camera/image/compressed", IMAGE[flavour]),
        ("/cmd_vel", TWIST[flavour]),
    ):
        assert call(session, "/rosapi/topic_type", topic=topic)["values"] == {"type": kind}
        assert send(session, op="subscribe", topic=topic, type=kind) == []
    refused = send(session, op="subscribe", topic="/odom", type="turtlesim/Pose", id="s")
    assert "has type" in refused[0]["msg"]
    raw = call(session, "/rosapi/topics_and_raw_types")["values"]
    texts = dict(zip(raw["topics"], raw["typedefs_full_text"], strict=True))
    assert "geometry_msgs/PoseWithCovariance pose" in texts["/odom"]
    assert "uint8[] data" in texts["/camera/image/compressed"]


def test_the_graph_shows_the_robot_node_and_no_turtles() -> None:
    session = Arena("2").session()
    topics = call(session, "/rosapi/topics")["values"]["topics"]
    assert {"/cmd_vel", "/odom", "/camera/image/compressed"} <= set(topics)
    assert not any("turtle" in t for t in topics)
    assert "/diffdrive" in call(session, "/rosapi/nodes")["values"]["nodes"]
    details = call(session, "/rosapi/node_details", node="/diffdrive")["values"]
    assert "/cmd_vel" in details["subscribing"]
    assert {"/odom", "/camera/image/compressed"} <= set(details["publishing"])
    services = call(session, "/rosapi/services")["values"]["services"]
    assert all(s.startswith("/rosapi/") for s in services)


@pytest.mark.parametrize("topic", ["/odom", "/camera/image/compressed"])
def test_what_the_robot_publishes_cannot_be_published_by_a_client(topic: str) -> None:
    arena = Arena()
    session = arena.session()
    before = arena.sim.robot.state()
    for op in ({"op": "advertise", "topic": topic}, {"op": "publish", "topic": topic, "msg": {}}):
        [status] = session.receive(json.dumps({**op, "id": "x"}))
        assert "published by the simulator only" in status["msg"]
    arena.tick(5)
    assert arena.sim.robot.state() == before


@pytest.mark.parametrize(
    "msg",
    [{"linear": {"x": "fast"}}, {"linear": {"x": 1e400}}, {"spin": 1}, {"angular": {"z": None}}],
)
def test_a_bad_twist_is_refused_and_moves_nothing(msg: Json) -> None:
    arena = Arena()
    session = arena.session()
    text = json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": msg, "id": "p"})
    [status] = session.receive(text.replace("Infinity", "1e400"))
    assert status["level"] == "error"
    arena.tick(5)
    assert arena.sim.robot.state().x == arena.hub.sim.arena.start.x


def test_turtlesim_topics_and_services_are_not_here() -> None:
    session = Arena().session()
    [status] = send(session, op="subscribe", topic="/turtle1/pose", id="s")
    assert "unknown topic" in status["msg"] and "/odom" in status["msg"]
    reply = call(session, "/spawn", x=1.0, y=1.0)
    assert reply["result"] is False and "unknown service" in reply["values"]


def test_cmd_vel_subscribers_get_what_is_published() -> None:
    arena = Arena()
    watcher, driver = arena.session(), arena.session()
    send(watcher, op="subscribe", topic="/cmd_vel")
    send(driver, op="publish", topic="/cmd_vel", msg={"linear": {"x": 0.2}, "angular": {"z": 0.1}})
    [twist] = published(watcher, "/cmd_vel")
    assert twist["linear"]["x"] == 0.2 and twist["angular"]["z"] == 0.1


def test_the_camera_is_wanted_only_while_someone_subscribes() -> None:
    arena = Arena()
    first, second = arena.session(), arena.session()
    assert not arena.hub.camera_wanted()
    send(first, op="subscribe", topic="/camera/image/compressed", id="a")
    send(second, op="subscribe", topic="camera/image/compressed", id="b")
    assert arena.hub.camera_wanted()
    send(first, op="unsubscribe", topic="/camera/image/compressed", id="a")
    assert arena.hub.camera_wanted()
    second.close()
    assert not arena.hub.camera_wanted()


def test_a_frame_reaches_the_camera_subscribers_latest_first() -> None:
    arena = Arena("1")
    session = arena.session()
    send(session, op="subscribe", topic="/camera/image/compressed")
    assert published(session, "/camera/image/compressed") == []
    arena.hub.publish_frame(b"\xff\xd8first", 5.5)
    arena.hub.publish_frame(b"\xff\xd8second", 5.6)
    [frame] = published(session, "/camera/image/compressed")
    assert frame["format"] == "jpeg"
    assert base64.b64decode(frame["data"]) == b"\xff\xd8second"
    assert frame["header"]["seq"] == 2 and frame["header"]["stamp"]["secs"] == 5
    assert published(session, "/camera/image/compressed") == []
