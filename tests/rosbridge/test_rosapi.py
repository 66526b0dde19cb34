"""One ROS flavour per server: type names, rosapi's answers and their shapes, statuses."""

from __future__ import annotations

import json
from typing import Any

import pytest

from app.protocol.ros import RosFlavour
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import TurtleSim

# What each flavour's rosbridge/rosapi reports for turtle1's topics (docs F15).
POSE = {"1": "turtlesim/Pose", "2": "turtlesim/msg/Pose", "jazzy": "turtlesim_msgs/msg/Pose"}
TWIST = {
    "1": "geometry_msgs/Twist",
    "2": "geometry_msgs/msg/Twist",
    "jazzy": "geometry_msgs/msg/Twist",
}
SPAWN = {"1": "turtlesim/Spawn", "2": "turtlesim/srv/Spawn", "jazzy": "turtlesim_msgs/srv/Spawn"}
FLAVOURS: tuple[RosFlavour, ...] = ("1", "2", "jazzy")
WALL_TIME = 1_700_000_000.25


class Robot:
    """A hub of one flavour over a simulator with a hand-driven clock, and one client."""

    def __init__(self, flavour: RosFlavour) -> None:
        self.now = 0.0
        self.sim = TurtleSim(clock=lambda: self.now)
        self.hub = RosbridgeHub(self.sim, flavour, wall_clock=lambda: WALL_TIME)
        self.session = self.hub.open_session()

    def send(self, **message: Any) -> list[dict[str, Any]]:
        return self.session.receive(json.dumps(message))

    def call(self, service_name: str, /, **args: Any) -> dict[str, Any]:
        (reply,) = self.send(op="call_service", id="r", service=service_name, args=args)
        assert reply["op"] == "service_response"
        assert reply["result"] is True, reply
        values: dict[str, Any] = reply["values"]
        return values

    def tick(self, count: int = 1) -> None:
        for _ in range(count):
            self.now += TurtleSim.TICK_S
            self.sim.step()
            self.hub.tick(self.now)


@pytest.fixture(params=FLAVOURS)
def robot(request: pytest.FixtureRequest) -> Robot:
    return Robot(request.param)


def test_topics_are_the_real_graphs_in_the_flavours_names(robot: Robot) -> None:
    flavour = robot.hub.types.flavour
    values = robot.call("/rosapi/topics")
    topics = dict(zip(values["topics"], values["types"], strict=True))
    assert topics["/turtle1/pose"] == POSE[flavour]
    assert topics["/turtle1/cmd_vel"] == TWIST[flavour]
    assert "/turtle1/color_sensor" in topics
    assert "/rosout" in topics
    if flavour == "1":
        # The real ROS 1 stack (turtlesim, rosbridge, rosapi) lists 7 topics.
        assert len(topics) == 7
        assert topics["/rosout"] == "rosgraph_msgs/Log"
    else:
        assert topics["/rosout"] == "rcl_interfaces/msg/Log"
        assert "/parameter_events" in topics


def test_topics_and_raw_types_carry_parseable_definitions(robot: Robot) -> None:
    values = robot.call("/rosapi/topics_and_raw_types")
    assert len(values["topics"]) == len(values["types"]) == len(values["typedefs_full_text"])
    texts = dict(zip(values["topics"], values["typedefs_full_text"], strict=True))
    assert "float32 linear_velocity" in texts["/turtle1/pose"]
    twist = texts["/turtle1/cmd_vel"]
    assert twist.startswith("geometry_msgs/Vector3 linear\n")
    assert "\nMSG: geometry_msgs/Vector3\nfloat64 x" in twist


def test_topic_and_service_types(robot: Robot) -> None:
    flavour = robot.hub.types.flavour
    assert robot.call("/rosapi/topic_type", topic="/turtle1/pose") == {"type": POSE[flavour]}
    assert robot.call("/rosapi/topic_type", topic="turtle1/pose") == {"type": POSE[flavour]}
    assert robot.call("/rosapi/topic_type", topic="/turtle9/pose") == {"type": ""}
    assert robot.call("/rosapi/service_type", service="/spawn") == {"type": SPAWN[flavour]}
    services = robot.call("/rosapi/services")["services"]
    assert {"/spawn", "/turtle1/set_pen", "/rosapi/get_param", "/rosapi/node_details"} <= set(
        services
    )
    rosapi_type = robot.call("/rosapi/service_type", service="/rosapi/topics")["type"]
    assert rosapi_type == ("rosapi/Topics" if flavour == "1" else "rosapi_msgs/srv/Topics")


def test_nodes_and_node_details(robot: Robot) -> None:
    assert "/turtlesim" in robot.call("/rosapi/nodes")["nodes"]
    details = robot.call("/rosapi/node_details", node="/turtlesim")
    assert set(details) == {"subscribing", "publishing", "services"}
    assert "/turtle1/pose" in details["publishing"]
    assert "/turtle1/cmd_vel" in details["subscribing"]
    assert "/spawn" in details["services"]
    assert robot.call("/rosapi/node_details", node="/nobody") == {
        "subscribing": [],
        "publishing": [],
        "services": [],
    }


def test_background_parameters_in_each_flavours_shape(robot: Robot) -> None:
    ros1 = robot.hub.types.flavour == "1"
    sep = "/" if ros1 else ":"
    names = robot.call("/rosapi/get_param_names")["names"]
    for channel, default in (("r", 69), ("g", 86), ("b", 255)):
        name = f"/turtlesim{sep}background_{channel}"
        assert name in names
        reply = robot.call("/rosapi/get_param", name=name)
        assert json.loads(reply["value"]) == default
        if not ros1:
            assert reply["successful"] is True
    name = f"/turtlesim{sep}background_r"
    set_reply = robot.call("/rosapi/set_param", name=name, value="150")
    assert set_reply == ({} if ros1 else {"successful": True, "reason": ""})
    assert json.loads(robot.call("/rosapi/get_param", name=name)["value"]) == 150


def test_ros2_refuses_a_parameter_value_of_the_wrong_kind() -> None:
    robot = Robot("2")
    reply = robot.call("/rosapi/set_param", name="/turtlesim:background_g", value="300")
    assert reply["successful"] is False
    assert "0..255" in reply["reason"]
    reply = robot.call("/rosapi/get_param", name="/turtlesim:nothing", default_value="7")
    assert (reply["successful"], json.loads(reply["value"])) == (False, 7)


def test_set_param_needs_json_text(robot: Robot) -> None:
    (reply,) = robot.send(
        op="call_service",
        service="/rosapi/set_param",
        args={"name": "/turtlesim/background_r", "value": "not json"},
    )
    assert reply["result"] is False
    assert "JSON" in reply["values"]


def test_get_time_in_each_flavours_shape(robot: Robot) -> None:
    time = robot.call("/rosapi/get_time")["time"]
    if robot.hub.types.flavour == "1":
        assert time == {"secs": 1_700_000_000, "nsecs": 250_000_000}
    else:
        assert time == {"sec": 1_700_000_000, "nanosec": 250_000_000}


def test_jazzy_moves_sideways_only_with_the_holonomic_parameter() -> None:
    robot = Robot("jazzy")
    start = robot.sim.pose("turtle1").y
    sideways = {"linear": {"y": 1.0}}
    assert robot.send(op="publish", topic="/turtle1/cmd_vel", msg=sideways) == []
    robot.tick(10)
    assert robot.sim.pose("turtle1").y == pytest.approx(start)
    assert robot.call("/rosapi/set_param", name="/turtlesim:holonomic", value="true")["successful"]
    robot.send(op="publish", topic="/turtle1/cmd_vel", msg=sideways)
    robot.tick(10)
    assert robot.sim.pose("turtle1").y == pytest.approx(start + 0.16)


@pytest.mark.parametrize(
    ("flavour", "accepted", "refused"),
    [
        ("1", ["turtlesim/Pose"], ["turtlesim/msg/Pose", "turtlesim_msgs/msg/Pose"]),
        ("2", ["turtlesim/Pose", "turtlesim/msg/Pose"], ["turtlesim_msgs/msg/Pose"]),
        ("jazzy", ["turtlesim_msgs/msg/Pose", "turtlesim_msgs/Pose"], ["turtlesim/msg/Pose"]),
    ],
)
def test_subscribe_accepts_only_the_flavours_spellings(
    flavour: RosFlavour, accepted: list[str], refused: list[str]
) -> None:
    robot = Robot(flavour)
    robot.send(op="set_level", level="error")
    for type_name in accepted:
        assert robot.send(op="subscribe", topic="/turtle1/pose", type=type_name) == []
    for type_name in refused:
        (error,) = robot.send(op="subscribe", id="s", topic="/turtle1/pose", type=type_name)
        assert error["op"] == "status"
        assert POSE[flavour] in error["msg"]


def test_no_status_for_a_request_that_cannot_be_served_unless_asked_for(robot: Robot) -> None:
    # Current rosbridge_suite sends no status at all; a failed call is a service_response.
    assert robot.send(op="subscribe", topic="/chatter") == []
    (reply,) = robot.send(op="call_service", id=3, service="/kill", args={"name": "nobody"})
    assert (reply["op"], reply["result"], reply["id"]) == ("service_response", False, 3)
    assert "nobody" in reply["values"]
    robot.send(op="set_level", level="error")
    (status,) = robot.send(op="subscribe", topic="/chatter")
    assert (status["op"], status["level"]) == ("status", "error")


def test_a_frame_that_is_no_rosbridge_message_gets_a_status_unless_none_was_asked(
    robot: Robot,
) -> None:
    # No rosbridge client sends these: they are told why, not met with silence (issue 37.2).
    for message in ({"op": "fly"}, {"op": ["publish"]}, {"op": "subscribe", "topic": 5}):
        (status,) = robot.send(**message)
        assert (status["op"], status["level"]) == ("status", "error")
    robot.send(op="set_level", level="none")
    assert robot.send(op="fly") == []


def test_graph_topics_we_do_not_simulate_say_so(robot: Robot) -> None:
    robot.send(op="set_level", level="error")
    (error,) = robot.send(op="subscribe", topic="/turtle1/color_sensor")
    assert "publishes nothing" in error["msg"]


def test_published_pose_fields_are_float32(robot: Robot) -> None:
    robot.send(op="subscribe", topic="/turtle1/pose")
    robot.tick()
    (publication,) = robot.session.take_publications()
    # turtlesim's centre, 499/90 m, as a float32 and not as a double.
    assert publication["msg"]["x"] == 5.544444561004639
