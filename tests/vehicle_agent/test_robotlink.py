"""Robot links: the in-process simulator, and the rosbridge link against this server's
/rosbridge."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

import pytest

from app.protocol.ros import RosFlavour
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.helpers.sockets import rosbridge_url
from vehicle_agent.core.control import Pose
from vehicle_agent.robotlink import RobotLink, RobotLinkError, RosbridgeLink, SimLink
from vehicle_agent.rosbridge_client import RosbridgeClient


class PoseWatch:
    """Collects pose updates and lets a test await a condition on them."""

    def __init__(self) -> None:
        self.poses: list[Pose] = []
        self._changed = asyncio.Event()

    def __call__(self, pose: Pose) -> None:
        self.poses.append(pose)
        self._changed.set()

    async def until(self, condition: object, timeout: float = 10.0) -> Pose:
        assert callable(condition)
        async with asyncio.timeout(timeout):
            while True:
                if self.poses and condition(self.poses[-1]):
                    return self.poses[-1]
                self._changed.clear()
                await self._changed.wait()


async def turn_and_stop(turtle: RobotLink) -> None:
    watch = PoseWatch()
    await turtle.start(watch)
    try:
        first = await watch.until(lambda p: True)
        assert first.theta == pytest.approx(0.0)
        # Keep commanding (turtlesim drops a command after 1 s) until the turtle faces up.
        async with asyncio.timeout(20):
            while watch.poses[-1].theta < math.pi / 4:
                turtle.publish(0.0, 1.5)
                await asyncio.sleep(0.1)
        turtle.publish(0.0, 0.0)
        await asyncio.sleep(0.3)  # let the zero Twist reach the turtle
        stopped = watch.poses[-1].theta
        await asyncio.sleep(0.5)
        assert watch.poses[-1].theta == pytest.approx(stopped, abs=1e-6)
        assert watch.poses[-1].x == pytest.approx(first.x)  # turning in place
    finally:
        await turtle.close()


async def test_the_sim_link_turns_and_stops() -> None:
    turtle = SimLink()
    await turn_and_stop(turtle)
    # Pose updates come on turtlesim's 16 ms tick.
    assert turtle.sim.pose("turtle1").theta > math.pi / 4


# What each flavour's robot reports for /turtle1/pose (docs/turtlesim-facts.md F15).
POSE_TYPE = {"1": "turtlesim/Pose", "2": "turtlesim/msg/Pose", "jazzy": "turtlesim_msgs/msg/Pose"}


@pytest.mark.parametrize("flavour", ["1", "2", "jazzy"])
async def test_the_rosbridge_link_learns_the_robots_flavour(
    start_server: Callable[[Settings], RunningServer], flavour: RosFlavour
) -> None:
    robot = start_server(Settings(environment="development", token=None, ros=flavour))
    turtle = RosbridgeLink(RosbridgeClient(rosbridge_url(robot)))  # --ros auto
    await turn_and_stop(turtle)
    assert turtle.types is not None
    assert (turtle.types.flavour, turtle.types.from_robot) == (flavour, True)
    assert turtle.types.pose == POSE_TYPE[flavour]


async def test_the_robots_answer_beats_a_wrong_setting(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    # A Jazzy robot refuses turtlesim/Pose; told "--ros 1", the agent still drives it.
    robot = start_server(Settings(environment="development", token=None, ros="jazzy"))
    turtle = RosbridgeLink(RosbridgeClient(rosbridge_url(robot)), ros="1")
    await turn_and_stop(turtle)
    assert turtle.types is not None
    assert turtle.types.flavour == "jazzy"


async def test_dead_rosbridge_is_named() -> None:
    turtle = RosbridgeLink(RosbridgeClient("ws://127.0.0.1:9/rosbridge"))
    # Nothing listens on port 9: refused at once, and said so (not a wait for the timeout).
    with pytest.raises(
        RobotLinkError, match=r"rosbridge at ws://127\.0\.0\.1:9/rosbridge: connection refused"
    ):
        await turtle.start(lambda pose: None)


def test_the_ros_setting_must_be_one_the_agent_knows() -> None:
    with pytest.raises(RobotLinkError, match="--ros must be one of"):
        RosbridgeLink(RosbridgeClient("ws://robot:9090"), ros="3")  # type: ignore[arg-type]
