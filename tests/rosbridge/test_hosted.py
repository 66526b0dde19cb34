"""The rosbridge hub carries other robots' topics between its clients (app/rosbridge/hosted.py):
the types of a robot description only, each message checked against its topic's type."""

from __future__ import annotations

import json
from typing import Any

import pytest

from app.rosbridge.hosted import MAX_HOSTED_TOPICS
from app.rosbridge.protocol import RosbridgeSession
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import TurtleSim


@pytest.fixture
def hub() -> RosbridgeHub:
    return RosbridgeHub(TurtleSim())  # ROS 2, the default flavour


def client(hub: RosbridgeHub) -> RosbridgeSession:
    session = hub.open_session()
    assert send(session, op="set_level", level="error") == []
    return session


def send(session: RosbridgeSession, **message: Any) -> list[dict[str, Any]]:
    return session.receive(json.dumps(message))


def error(replies: list[dict[str, Any]]) -> str:
    (status,) = replies
    assert status["op"] == "status" and status["level"] == "error", replies
    text: str = status["msg"]
    return text


def topic_type(session: RosbridgeSession, topic: str) -> str:
    (reply,) = send(session, op="call_service", service="/rosapi/topic_type", args={"topic": topic})
    kind: str = reply["values"]["type"]
    return kind


STAMPED = {
    "header": {"stamp": {"sec": 1_700_000_000, "nanosec": 5}, "frame_id": "base_link"},
    "twist": {"linear": {"x": 0.2}, "angular": {"z": -1.0}},
}


def test_a_robots_velocity_topic_goes_from_publisher_to_subscriber(hub: RosbridgeHub) -> None:
    robot, agent = client(hub), client(hub)
    # The robot takes TwistStamped on /rover/base/cmd_vel (a /NAME/cmd_vel would be turtle NAME's
    # topic, a Twist); rosapi names the type from then on.
    kind = "geometry_msgs/msg/TwistStamped"
    assert send(robot, op="subscribe", topic="/rover/base/cmd_vel", type=kind) == []
    assert topic_type(agent, "/rover/base/cmd_vel") == kind
    assert (
        send(agent, op="advertise", topic="rover/base/cmd_vel", type="geometry_msgs/TwistStamped")
        == []
    )
    assert send(agent, op="publish", topic="rover/base/cmd_vel", msg=STAMPED) == []
    (publication,) = robot.take_publications()
    assert publication["topic"] == "/rover/base/cmd_vel"
    message = publication["msg"]
    assert message["header"] == STAMPED["header"]
    # Missing fields are filled in, as rosbridge fills them.
    assert message["twist"]["linear"] == {"x": 0.2, "y": 0.0, "z": 0.0}
    assert agent.take_publications() == []  # the publisher did not subscribe
    # Nothing of it moves the turtle.
    assert hub.sim.pose("turtle1").linear_velocity == 0.0


def test_odometry_is_carried_too(hub: RosbridgeHub) -> None:
    robot, agent = client(hub), client(hub)
    assert send(agent, op="subscribe", topic="/odom", type="nav_msgs/msg/Odometry") == []
    assert send(robot, op="advertise", topic="/odom", type="nav_msgs/msg/Odometry") == []
    odom = {"pose": {"pose": {"position": {"x": 1.5}, "orientation": {"z": 0.6, "w": 0.8}}}}
    assert send(robot, op="publish", topic="/odom", msg=odom) == []
    (publication,) = agent.take_publications()
    pose = publication["msg"]["pose"]
    assert pose["pose"]["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.6, "w": 0.8}
    assert len(pose["covariance"]) == 36


@pytest.mark.parametrize(
    ("message", "words"),
    [
        ({"twist": {"linear": {"x": "fast"}}}, "twist.linear.x"),
        ({"twist": {"linear": {"x": 0.1}}, "wheels": 2}, "wheels"),
        ({"header": {"stamp": {"secs": 1, "nsecs": 0}}}, "ROS 2 time has sec and nanosec"),
        ({"linear": {"x": 1.0}}, "linear"),  # a Twist on a TwistStamped topic
    ],
)
def test_a_message_not_of_the_topics_type_is_refused_and_goes_nowhere(
    hub: RosbridgeHub, message: dict[str, Any], words: str
) -> None:
    robot, agent = client(hub), client(hub)
    send(robot, op="subscribe", topic="/cmd_vel", type="geometry_msgs/msg/TwistStamped")
    text = error(send(agent, op="publish", id="p", topic="/cmd_vel", msg=message))
    assert words in text and "/cmd_vel" in text
    assert robot.take_publications() == []


@pytest.mark.parametrize(
    ("message", "words"),
    [
        # Not a type of a robot description: still an unknown topic, as before.
        ({"op": "advertise", "topic": "/chatter", "type": "std_msgs/String"}, "unknown topic"),
        ({"op": "subscribe", "topic": "/chatter", "type": "std_msgs/msg/String"}, "unknown topic"),
        # Untyped, and nobody hosts it: nothing says what it carries.
        ({"op": "subscribe", "topic": "/odom"}, "give its type"),
        # A ROS 1 spelling on a ROS 2 server.
        ({"op": "advertise", "topic": "/odom", "type": "nav_msgs/Odometry/x"}, "unknown topic"),
        ({"op": "advertise", "topic": "/odom", "type": "rosgraph_msgs/Log"}, "unknown topic"),
        # Published before anyone hosts it.
        ({"op": "publish", "topic": "/odom", "msg": {}}, "unknown topic"),
        # On the turtlesim graph, but not simulated: not hosted either.
        ({"op": "subscribe", "topic": "/rosout", "type": "rcl_interfaces/msg/Log"}, "publishes"),
    ],
)
def test_what_cannot_be_hosted_is_refused(
    hub: RosbridgeHub, message: dict[str, Any], words: str
) -> None:
    session = client(hub)
    assert words in error(send(session, id="r", **message))
    if message["topic"] != "/rosout":  # on the graph, though nothing is published on it
        assert topic_type(session, message["topic"]) == ""


def test_one_topic_one_type(hub: RosbridgeHub) -> None:
    first, second = client(hub), client(hub)
    send(first, op="advertise", topic="/cmd_vel", type="geometry_msgs/msg/Twist")
    text = error(send(second, op="subscribe", topic="/cmd_vel", type="nav_msgs/msg/Odometry"))
    assert "geometry_msgs/msg/Twist" in text
    # The same type spelled the short way, or no type at all, is the same topic.
    assert send(second, op="subscribe", topic="/cmd_vel", type="geometry_msgs/Twist") == []
    assert send(second, op="subscribe", id="2", topic="cmd_vel") == []


def test_a_topic_is_hosted_while_anyone_advertises_or_subscribes(hub: RosbridgeHub) -> None:
    robot, agent = client(hub), client(hub)
    send(robot, op="advertise", topic="/odom", type="nav_msgs/msg/Odometry")
    send(agent, op="subscribe", topic="odom", type="nav_msgs/msg/Odometry")
    topics = send(robot, op="call_service", service="/rosapi/topics")[0]["values"]
    assert "/odom" in topics["topics"]
    send(robot, op="unadvertise", topic="/odom")
    assert topic_type(agent, "/odom") == "nav_msgs/msg/Odometry"  # still subscribed
    send(agent, op="unsubscribe", topic="odom")
    assert topic_type(agent, "/odom") == ""
    # A client that goes away takes its topics with it.
    send(robot, op="advertise", topic="/cmd_vel", type="geometry_msgs/msg/Twist")
    robot.close()
    assert topic_type(agent, "/cmd_vel") == ""
    # Now any type may take the name.
    assert send(agent, op="subscribe", topic="/cmd_vel", type="nav_msgs/msg/Odometry") == []


def test_rosapi_describes_the_turtles_topics_beside_hosted_ones(hub: RosbridgeHub) -> None:
    session = client(hub)
    send(
        session,
        op="advertise",
        topic="/camera/image/compressed",
        type="sensor_msgs/msg/CompressedImage",
    )
    (reply,) = send(session, op="call_service", service="/rosapi/topics_and_raw_types")
    values = reply["values"]
    assert reply["result"] is True
    hosted = values["topics"].index("/camera/image/compressed")
    assert values["types"][hosted] == "sensor_msgs/msg/CompressedImage"
    assert "float32 theta" in values["typedefs_full_text"][values["topics"].index("/turtle1/pose")]
    (details,) = send(
        session, op="call_service", service="/rosapi/node_details", args={"node": "/turtlesim"}
    )
    assert "/camera/image/compressed" not in str(details["values"])


def test_at_most_so_many_hosted_topics(hub: RosbridgeHub) -> None:
    sessions = [client(hub) for _ in range(MAX_HOSTED_TOPICS // 32 + 1)]
    made = 0
    for k in range(MAX_HOSTED_TOPICS):
        session = sessions[k // 32]
        replies = send(
            session, op="advertise", topic=f"/robot{k}/base/cmd_vel", type="geometry_msgs/Twist"
        )
        assert replies == [], replies
        made += 1
    last = sessions[-1]
    text = error(
        send(last, op="advertise", topic="/one_more/base/cmd_vel", type="geometry_msgs/Twist")
    )
    assert f"at most {MAX_HOSTED_TOPICS}" in text
    assert made == MAX_HOSTED_TOPICS
