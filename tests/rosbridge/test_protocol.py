"""The sans-I/O rosbridge v2 session over TurtleSim: every op and every error case."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from app.rosbridge.protocol import RosbridgeSession
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import TurtleSim

CENTRE = TurtleSim.WORLD_SIZE / 2
# A number too large for a float would parse as infinity: the JSON edge refuses it.
INFINITE_TWIST = '{"op": "publish", "topic": "turtle1/cmd_vel", "msg": {"linear": {"x": 1e999}}}'


class World:
    """A hub over a simulator whose clock the test moves, one 16 ms tick at a time."""

    def __init__(self) -> None:
        self.now = 10.0
        self.sim = TurtleSim(clock=lambda: self.now)
        self.hub = RosbridgeHub(self.sim)

    def tick(self, count: int = 1) -> None:
        for _ in range(count):
            self.now += TurtleSim.TICK_S
            self.sim.step()
            self.hub.tick(self.now)

    def tick_and_take(self, session: RosbridgeSession) -> list[dict[str, Any]]:
        """One tick, then what ``session`` is sent, as to a client that reads every tick."""
        self.tick()
        return session.take_publications()


@pytest.fixture
def world() -> World:
    return World()


@pytest.fixture
def session(world: World) -> RosbridgeSession:
    """A client that asked for status errors: most tests here read the error wording from them.

    Without ``set_level`` a client gets no status at all (see the status-level tests below).
    """
    session = world.hub.open_session()
    assert send(session, op="set_level", level="error") == []
    return session


def send(session: RosbridgeSession, **message: Any) -> list[dict[str, Any]]:
    return session.receive(json.dumps(message))


def only_error(replies: list[dict[str, Any]]) -> dict[str, Any]:
    """The single status error among the replies."""
    errors = [r for r in replies if r["op"] == "status"]
    assert len(errors) == 1, replies
    assert errors[0]["level"] == "error"
    return errors[0]


def refusal(session: RosbridgeSession, words: str, **message: Any) -> dict[str, Any]:
    """Send ``message``: the one error it gets names ``words`` and echoes the message's id."""
    error = only_error(send(session, **message))
    assert words in error["msg"]
    assert error["id"] == message["id"]
    return error


def service_call(session: RosbridgeSession, service: str, **args: Any) -> dict[str, Any]:
    """Call a service and return its service_response."""
    replies = send(session, op="call_service", id="c1", service=service, args=args)
    (response,) = [r for r in replies if r["op"] == "service_response"]
    assert response["id"] == "c1"
    assert response["service"] == service
    return response


def poses(publications: list[dict[str, Any]], topic: str) -> list[dict[str, Any]]:
    return [p["msg"] for p in publications if p["op"] == "publish" and p["topic"] == topic]


# -- malformed frames and unknown ops --------------------------------------------------------


@pytest.mark.parametrize(
    ("frame", "words"),
    [
        ("{not json", "malformed JSON"),
        ('{"op": "publish", "topic": "/turtle1/cmd_vel", "msg": {"linear": {"x": NaN}}}', "NaN"),
        (INFINITE_TWIST, "1e999"),
        ("[" * 50_000, "nested deeper than"),
        ("[1, 2]", "JSON object"),
        ('"publish"', "JSON object"),
        ('{"topic": "/turtle1/pose"}', "'op'"),
        ('{"op": 7}', "'op'"),
    ],
)
def test_malformed_frames_get_a_status_error(
    session: RosbridgeSession, frame: str, words: str
) -> None:
    error = only_error(session.receive(frame))
    assert words in error["msg"]


def test_unknown_op_names_it_and_echoes_the_id(session: RosbridgeSession) -> None:
    refusal(session, "fly", op="fly", id="f1")


def test_integer_ids_are_echoed_too(session: RosbridgeSession) -> None:
    assert only_error(send(session, op="fly", id=42))["id"] == 42


def test_an_id_of_the_wrong_type_is_reported_and_not_echoed(session: RosbridgeSession) -> None:
    error = only_error(send(session, op="subscribe", id=[1], topic="/turtle1/pose"))
    assert "id" in error["msg"]
    assert "id" not in error


@pytest.mark.parametrize(
    ("message", "field"),
    [
        ({"op": "advertise"}, "topic"),
        ({"op": "unadvertise"}, "topic"),
        ({"op": "publish", "topic": "/turtle1/cmd_vel"}, "msg"),
        ({"op": "publish", "msg": {}}, "topic"),
        ({"op": "subscribe"}, "topic"),
        ({"op": "unsubscribe"}, "topic"),
        ({"op": "call_service"}, "service"),
        ({"op": "set_level"}, "level"),
        ({"op": "subscribe", "topic": 5}, "topic"),
        ({"op": "publish", "topic": "/turtle1/cmd_vel", "msg": [1, 2]}, "msg"),
        ({"op": "subscribe", "topic": "/turtle1/pose", "throttle_rate": -1}, "throttle_rate"),
        ({"op": "subscribe", "topic": "/turtle1/pose", "throttle_rate": "10"}, "throttle_rate"),
        ({"op": "subscribe", "topic": "/turtle1/pose", "queue_length": 1.5}, "queue_length"),
        ({"op": "subscribe", "topic": "/turtle1/pose", "compression": "png"}, "compression"),
        ({"op": "call_service", "service": "/spawn", "args": [1, 2]}, "args"),
        ({"op": "set_level", "level": "loud"}, "level"),
    ],
)
def test_missing_and_mistyped_fields_are_named(
    session: RosbridgeSession, message: dict[str, Any], field: str
) -> None:
    error = refusal(session, field, id="m1", **message)
    assert error["msg"].startswith(message["op"])


# -- subscribe / unsubscribe ------------------------------------------------------------------


def test_subscribed_pose_arrives_every_tick(world: World, session: RosbridgeSession) -> None:
    assert send(session, op="subscribe", id="s1", topic="/turtle1/pose") == []
    msgs = []
    for _ in range(3):  # a client that reads: its socket is free after every tick
        world.tick()
        msgs += poses(session.take_publications(), "/turtle1/pose")
    assert len(msgs) == 3
    assert msgs[0] == {
        "x": pytest.approx(CENTRE),
        "y": pytest.approx(CENTRE),
        "theta": 0.0,
        "linear_velocity": 0.0,
        "angular_velocity": 0.0,
    }
    assert session.take_publications() == []


def test_no_publications_without_a_subscription(world: World, session: RosbridgeSession) -> None:
    world.tick(5)
    assert session.take_publications() == []


def test_topic_spelling_is_echoed_and_types_of_ros1_and_ros2_accepted(
    world: World, session: RosbridgeSession
) -> None:
    assert send(session, op="subscribe", topic="turtle1/pose", type="turtlesim/Pose") == []
    assert send(session, op="subscribe", topic="/turtle1/pose", type="turtlesim/msg/Pose") == []
    world.tick()
    publications = session.take_publications()
    assert sorted(p["topic"] for p in publications) == ["/turtle1/pose", "turtle1/pose"]


def test_throttle_rate_spaces_publications(world: World, session: RosbridgeSession) -> None:
    send(session, op="subscribe", topic="/turtle1/pose", throttle_rate=100)
    count = 0
    for _ in range(63):  # about one second
        world.tick()
        count += len(session.take_publications())
    # One per 100 ms, rounded up to whole 16 ms ticks (112 ms): 9 to 10 in a second.
    assert 8 <= count <= 11


def test_throttle_with_queue_sends_the_latest_pose_when_the_period_is_over(
    world: World, session: RosbridgeSession
) -> None:
    # A newer pose supersedes the older ones: what waits out the throttle is the latest.
    send(session, op="call_service", service="/turtle1/teleport_absolute", args={"x": 1.0})
    send(session, op="publish", topic="/turtle1/cmd_vel", msg={"linear": {"x": 2.0}})
    send(session, op="subscribe", topic="/turtle1/pose", throttle_rate=1000, queue_length=3)
    world.tick()  # first message goes out at once: nothing sent before
    first = poses(session.take_publications(), "/turtle1/pose")
    assert len(first) == 1
    world.tick(20)  # throttled: the latest 3 wait in the queue
    assert session.take_publications() == []
    world.tick(45)  # past one second: the oldest queued message leaves
    (second,) = poses(session.take_publications(), "/turtle1/pose")
    assert first[0]["x"] < second["x"]
    # The one sent is from the end of the first second, not from the tick right after the
    # first publication.
    assert second["x"] > first[0]["x"] + 2.0 * TurtleSim.TICK_S * 50


def test_several_ids_on_one_topic_share_one_stream_with_the_smallest_throttle(
    world: World, session: RosbridgeSession
) -> None:
    send(session, op="subscribe", id="slow", topic="/turtle1/pose", throttle_rate=1000)
    send(session, op="subscribe", id="fast", topic="/turtle1/pose")
    assert sum(len(world.tick_and_take(session)) for _ in range(4)) == 4
    assert send(session, op="unsubscribe", id="fast", topic="/turtle1/pose") == []
    assert sum(len(world.tick_and_take(session)) for _ in range(4)) <= 1


def test_unsubscribe_stops_publications(world: World, session: RosbridgeSession) -> None:
    send(session, op="subscribe", id="s1", topic="/turtle1/pose")
    assert send(session, op="unsubscribe", id="s1", topic="/turtle1/pose") == []
    world.tick(3)
    assert session.take_publications() == []
    assert session.subscribed_topics() == []


def test_unsubscribe_without_id_drops_every_subscription_on_the_topic(
    world: World, session: RosbridgeSession
) -> None:
    send(session, op="subscribe", id="a", topic="/turtle1/pose")
    send(session, op="subscribe", id="b", topic="/turtle1/pose")
    assert send(session, op="unsubscribe", topic="/turtle1/pose") == []
    world.tick()
    assert session.take_publications() == []


def test_unsubscribe_of_what_was_not_subscribed_is_a_warning(session: RosbridgeSession) -> None:
    assert send(session, op="unsubscribe", id="u", topic="/turtle1/pose") == []
    send(session, op="set_level", level="warning")
    (warning,) = send(session, op="unsubscribe", id="u", topic="/turtle1/pose")
    assert warning["level"] == "warning"
    assert warning["id"] == "u"


@pytest.mark.parametrize(
    ("message", "words"),
    [
        ({"op": "subscribe", "topic": "/chatter"}, "unknown topic"),
        ({"op": "subscribe", "topic": "/turtle1/odom"}, "unknown topic"),
        ({"op": "subscribe", "topic": "/turtle9/pose"}, "turtle9"),
        # The hub serves ROS 2 (the default flavour), so the error names the ROS 2 type.
        (
            {"op": "subscribe", "topic": "/turtle1/pose", "type": "geometry_msgs/Twist"},
            "turtlesim/msg/Pose",
        ),
        (
            {"op": "advertise", "topic": "/turtle1/cmd_vel", "type": "std_msgs/String"},
            "geometry_msgs/msg/Twist",
        ),
        ({"op": "advertise", "topic": "/turtle1/pose"}, "simulator only"),
        ({"op": "advertise", "topic": "/chatter", "type": "std_msgs/String"}, "unknown topic"),
    ],
)
def test_subscribe_or_advertise_of_what_does_not_exist_is_an_error(
    session: RosbridgeSession, message: dict[str, Any], words: str
) -> None:
    refusal(session, words, id="r1", **message)
    assert session.subscribed_topics() == []


def test_subscription_survives_reset(world: World, session: RosbridgeSession) -> None:
    send(session, op="call_service", service="/turtle1/teleport_absolute", args={"x": 1.0})
    send(session, op="subscribe", topic="/turtle1/pose")
    assert service_call(session, "/reset")["result"] is True
    world.tick()
    (pose,) = poses(session.take_publications(), "/turtle1/pose")
    assert pose["x"] == pytest.approx(CENTRE)


def test_closed_session_gets_nothing_more(world: World, session: RosbridgeSession) -> None:
    send(session, op="subscribe", topic="/turtle1/pose")
    session.close()
    world.tick(2)
    assert session.take_publications() == []
    assert session not in world.hub.sessions


# -- advertise / publish ---------------------------------------------------------------------


def test_publish_cmd_vel_drives_the_turtle(world: World, session: RosbridgeSession) -> None:
    twist = {"linear": {"x": 1.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0, "y": 0, "z": 0.5}}
    assert send(session, op="publish", topic="/turtle1/cmd_vel", msg=twist) == []
    world.tick(10)
    pose = world.sim.pose("turtle1")
    assert pose.linear_velocity == 1.0
    assert pose.angular_velocity == 0.5
    assert pose.x > CENTRE
    assert pose.theta > 0


def test_publish_without_leading_slash_and_missing_fields_default_to_zero(
    world: World, session: RosbridgeSession
) -> None:
    assert send(session, op="publish", topic="turtle1/cmd_vel", msg={"angular": {"z": 1}}) == []
    world.tick(5)
    pose = world.sim.pose("turtle1")
    assert pose.theta == pytest.approx(5 * 0.016)
    assert pose.x == pytest.approx(CENTRE)


def test_advertise_then_publish_then_unadvertise(world: World, session: RosbridgeSession) -> None:
    for type_name in ("geometry_msgs/Twist", "geometry_msgs/msg/Twist", None):
        message: dict[str, Any] = {"op": "advertise", "id": "a1", "topic": "/turtle1/cmd_vel"}
        if type_name is not None:
            message["type"] = type_name
        assert send(session, **message) == []
    assert send(session, op="publish", topic="/turtle1/cmd_vel", msg={"linear": {"x": 1}}) == []
    send(session, op="set_level", level="warning")
    assert send(session, op="unadvertise", id="a1", topic="/turtle1/cmd_vel") == []
    (warning,) = send(session, op="unadvertise", id="a2", topic="/turtle1/cmd_vel")
    assert warning["level"] == "warning"


@pytest.mark.parametrize(
    ("message", "words"),
    [
        ({"topic": "/turtle9/cmd_vel", "msg": {"linear": {"x": 1}}}, "turtle9"),
        ({"topic": "/turtle1/pose", "msg": {"x": 1}}, "simulator only"),
        ({"topic": "/chatter", "msg": {"data": "hi"}}, "unknown topic"),
        ({"topic": "/turtle1/cmd_vel", "msg": {"linear": {"x": "fast"}}}, "linear.x"),
        ({"topic": "/turtle1/cmd_vel", "msg": {"linear": {"x": True}}}, "linear.x"),
        ({"topic": "/turtle1/cmd_vel", "msg": {"speed": 1}}, "speed"),
        ({"topic": "/turtle1/cmd_vel", "msg": {"linear": 5}}, "linear"),
    ],
)
def test_bad_publish_is_an_error_and_changes_nothing(
    world: World, session: RosbridgeSession, message: dict[str, Any], words: str
) -> None:
    refusal(session, words, op="publish", id="p1", **message)
    world.tick(5)
    pose = world.sim.pose("turtle1")
    assert (pose.x, pose.theta, pose.linear_velocity) == (pytest.approx(CENTRE), 0.0, 0.0)
    # The session keeps working after the error.
    assert send(session, op="publish", topic="/turtle1/cmd_vel", msg={"linear": {"x": 1}}) == []


def test_cmd_vel_is_delivered_to_its_subscribers_in_every_session(world: World) -> None:
    driver = world.hub.open_session()
    watcher = world.hub.open_session()
    assert send(watcher, op="subscribe", topic="/turtle1/cmd_vel", type="geometry_msgs/Twist") == []
    send(driver, op="publish", topic="/turtle1/cmd_vel", msg={"angular": {"z": 0.25}})
    world.tick()
    (twist,) = poses(watcher.take_publications(), "/turtle1/cmd_vel")
    assert twist == {
        "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": 0.25},
    }
    assert driver.take_publications() == []


# -- services ----------------------------------------------------------------------------------


def test_spawn_returns_the_new_name_and_its_pose_topic_exists(
    world: World, session: RosbridgeSession
) -> None:
    response = service_call(session, "/spawn", x=2.0, y=3.0, theta=0.5)
    assert response == {
        "op": "service_response",
        "service": "/spawn",
        "id": "c1",
        "values": {"name": "turtle2"},
        "result": True,
    }
    assert service_call(session, "spawn", x=1.0, y=1.0, name="leo")["values"] == {"name": "leo"}
    assert send(session, op="subscribe", topic="/turtle2/pose") == []
    world.tick()
    (pose,) = poses(session.take_publications(), "/turtle2/pose")
    assert (pose["x"], pose["y"], pose["theta"]) == pytest.approx((2.0, 3.0, 0.5))


def test_kill_removes_the_turtle(world: World, session: RosbridgeSession) -> None:
    service_call(session, "/spawn", name="leo")
    assert service_call(session, "/kill", name="leo") == {
        "op": "service_response",
        "service": "/kill",
        "id": "c1",
        "values": {},
        "result": True,
    }
    assert world.sim.names() == ["turtle1"]


def test_reset_and_clear(world: World, session: RosbridgeSession) -> None:
    service_call(session, "/spawn")
    service_call(session, "/turtle1/teleport_absolute", x=1.0, y=1.0)
    world.tick()  # teleports happen on the next tick, as in turtlesim
    assert service_call(session, "/clear")["result"] is True
    assert [len(s.points) for s in world.sim.strokes()] == [1, 1]
    assert world.sim.pose("turtle1").x == 1.0
    assert service_call(session, "/reset")["result"] is True
    assert world.sim.names() == ["turtle1"]
    assert world.sim.pose("turtle1").x == pytest.approx(CENTRE)


def test_teleports_move_the_turtle(world: World, session: RosbridgeSession) -> None:
    response = service_call(session, "/turtle1/teleport_absolute", x=2.0, y=3.0, theta=1.0)
    assert (response["result"], response["values"]) == (True, {})
    world.tick()  # teleports happen on the next tick, as in turtlesim
    pose = world.sim.pose("turtle1")
    assert (pose.x, pose.y, pose.theta) == pytest.approx((2.0, 3.0, 1.0))
    assert service_call(session, "turtle1/teleport_relative", linear=1.0, angular=-1.0)["result"]
    world.tick()
    pose = world.sim.pose("turtle1")
    assert (pose.x, pose.y, pose.theta) == pytest.approx((3.0, 3.0, 0.0))


def test_set_pen(world: World, session: RosbridgeSession) -> None:
    assert service_call(session, "/turtle1/set_pen", r=255, g=0, b=0, width=4, off=0)["result"]
    assert world.sim.pen("turtle1").r == 255
    assert service_call(session, "/turtle1/set_pen", r=1, g=2, b=3, width=1, off=True)["result"]
    assert world.sim.pen("turtle1").off is True


@pytest.mark.parametrize(
    ("service", "type_name"),
    [
        ("/spawn", "turtlesim/Spawn"),
        ("/spawn", "turtlesim/srv/Spawn"),
        ("/clear", "std_srvs/Empty"),
        ("/clear", "std_srvs/srv/Empty"),
        ("/turtle1/set_pen", "turtlesim/srv/SetPen"),
    ],
)
def test_ros1_and_ros2_service_types_are_accepted(
    session: RosbridgeSession, service: str, type_name: str
) -> None:
    replies = send(session, op="call_service", id=1, service=service, type=type_name, args={})
    (response,) = replies
    assert response["result"] is True


@pytest.mark.parametrize(
    ("service", "args", "type_name", "words"),
    [
        ("/teleport", {}, None, "unknown service"),
        ("/turtle1/fly", {}, None, "unknown service"),
        ("/turtle9/teleport_absolute", {"x": 1.0}, None, "turtle9"),
        ("/kill", {"name": "turtle9"}, None, "turtle9"),
        ("/spawn", {"name": "turtle1"}, None, "already exists"),
        ("/spawn", {"name": "bad name"}, None, "invalid"),
        ("/spawn", {"x": "left"}, None, "x"),
        ("/spawn", {"colour": "green"}, None, "colour"),
        ("/reset", {"now": True}, None, "now"),
        ("/turtle1/set_pen", {"r": 300}, None, "r"),
        # No case for a wrong call_service ``type``: rosbridge ignores that field, and so do we.
    ],
)
def test_failed_calls_answer_result_false_and_a_status_error(
    world: World,
    session: RosbridgeSession,
    service: str,
    args: dict[str, Any],
    type_name: str | None,
    words: str,
) -> None:
    message: dict[str, Any] = {"op": "call_service", "id": "c7", "service": service, "args": args}
    if type_name is not None:
        message["type"] = type_name
    replies = send(session, **message)
    error = only_error(replies)
    assert error["id"] == "c7"
    assert words in error["msg"]
    (response,) = [r for r in replies if r["op"] == "service_response"]
    assert response["result"] is False
    assert response["id"] == "c7"
    assert words in response["values"]
    assert world.sim.names() == ["turtle1"]


def test_rosapi_lists_topics_and_services_of_living_turtles(session: RosbridgeSession) -> None:
    # Before the graph was modelled this listed only cmd_vel and pose; a real robot's list also
    # has color_sensor, /rosout and /parameter_events (tests/rosbridge/test_rosapi.py).
    service_call(session, "/spawn", name="leo")
    topics = service_call(session, "/rosapi/topics")["values"]
    listed = dict(zip(topics["topics"], topics["types"], strict=True))
    assert listed["/leo/cmd_vel"] == "geometry_msgs/msg/Twist"
    assert listed["/leo/pose"] == "turtlesim/msg/Pose"
    assert not any(name.startswith("/turtle2/") for name in listed)
    services = set(service_call(session, "/rosapi/services")["values"]["services"])
    assert {"/spawn", "/kill", "/reset", "/clear", "/leo/set_pen"} <= services
    assert "/turtle2/set_pen" not in services
    # Every listed service can be called (the empty request is valid for these).
    for name in ("/clear", "/turtle1/set_pen", "/leo/teleport_relative"):
        assert name in services
        assert service_call(session, name)["result"] is True


def test_rosapi_topic_type(session: RosbridgeSession) -> None:
    assert service_call(session, "/rosapi/topic_type", topic="/turtle1/pose")["values"] == {
        "type": "turtlesim/msg/Pose"
    }
    assert service_call(session, "/rosapi/topic_type", topic="/turtle9/pose")["values"] == {
        "type": ""
    }


# -- status level -------------------------------------------------------------------------------


def test_set_level_none_silences_errors_but_not_service_responses(
    session: RosbridgeSession,
) -> None:
    assert send(session, op="set_level", level="none") == []
    assert send(session, op="fly") == []
    (response,) = send(session, op="call_service", id="c", service="/nowhere")
    assert response["result"] is False


def test_adapter_errors_respect_the_level(session: RosbridgeSession) -> None:
    assert only_error(session.error("binary frames are not supported"))["msg"].startswith("binary")
    send(session, op="set_level", level="none")
    assert session.error("too big") == []


def test_a_client_that_does_not_read_is_owed_only_the_latest_of_each_topic(
    world: World, session: RosbridgeSession
) -> None:
    # Issue 37.8: nothing piles up for a client that never reads; when it does read, each
    # subscription gives the newest message of its topic (latest wins).
    for n in range(2, 17):
        service_call(session, "/spawn", x=float(n) / 2, y=1.0)
    names = world.sim.names()
    for name in names:
        send(session, op="subscribe", topic=f"/{name}/pose")
    world.tick(1000)
    publications = session.take_publications()
    assert sorted(p["topic"] for p in publications) == sorted(f"/{n}/pose" for n in names)
    latest = world.sim.pose("turtle1").x
    (turtle1,) = poses(publications, "/turtle1/pose")
    assert turtle1["x"] == pytest.approx(latest, abs=1e-6)


def test_cmd_vel_subscribers_get_the_latest_queue_length_twists_they_have_not_had(
    world: World,
) -> None:
    driver, watcher, latest = (world.hub.open_session() for _ in range(3))
    send(watcher, op="subscribe", topic="/turtle1/cmd_vel", queue_length=3)
    send(latest, op="subscribe", topic="/turtle1/cmd_vel")
    for z in range(1, 6):
        send(driver, op="publish", topic="/turtle1/cmd_vel", msg={"angular": {"z": float(z)}})
    world.tick()
    got = [t["angular"]["z"] for t in poses(watcher.take_publications(), "/turtle1/cmd_vel")]
    assert got == [3.0, 4.0, 5.0]  # the latest 3, oldest first
    assert [t["angular"]["z"] for t in poses(latest.take_publications(), "/turtle1/cmd_vel")] == [
        5.0
    ]
    world.tick()
    assert watcher.take_publications() == []  # nothing new


def test_a_client_is_sent_at_most_125_publications_a_second_its_subscriptions_in_turn(
    world: World, session: RosbridgeSession
) -> None:
    for n in range(2, 17):
        service_call(session, "/spawn", x=float(n) / 2, y=1.0)
    for name in world.sim.names():
        send(session, op="subscribe", topic=f"/{name}/pose")
    per_topic: dict[str, int] = {}
    for _ in range(630):  # about ten seconds, read after every tick
        for publication in world.tick_and_take(session):
            per_topic[publication["topic"]] = per_topic.get(publication["topic"], 0) + 1
    # 16 topics at 62.5 poses a second would be 10,000; a client is sent 125 a second (and its
    # first 16 at once), and every subscription has its turn.
    assert sum(per_topic.values()) <= 16 + 125 * 630 * TurtleSim.TICK_S
    assert len(per_topic) == 16
    assert max(per_topic.values()) - min(per_topic.values()) <= 1


def test_many_sessions_with_their_own_subscriptions(world: World) -> None:
    sessions = [world.hub.open_session() for _ in range(20)]
    for i, s in enumerate(sessions):
        if i % 2 == 0:
            send(s, op="subscribe", topic="/turtle1/pose")
    counts = [0] * 20
    for _ in range(2):
        world.tick()
        counts = [n + len(s.take_publications()) for n, s in zip(counts, sessions, strict=True)]
    assert counts == [2 if i % 2 == 0 else 0 for i in range(20)]
    assert math.isfinite(world.sim.pose("turtle1").x)
