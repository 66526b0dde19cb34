"""The agent's links to the robot it drives: where its Twists go and where its pose comes from.

* :class:`SimLink` -- an in-process :class:`app.turtlesim.sim.TurtleSim` stepped by an asyncio
  task on turtlesim's fixed 16 ms tick (the agent's default: no server, no ROS).
* :class:`RosbridgeLink` -- any rosbridge v2 server over the agent's one rosbridge client
  (:mod:`vehicle_agent.rosbridge_client`): this project's ``/rosbridge`` endpoint or a real
  robot's ``rosbridge_server``, driving the robot a description names (:mod:`app.protocol.robot`:
  its velocity topic and type, its pose source). The types are learnt from the robot's rosapi
  ``topic_type``, falling back to the ``--ros`` setting (:func:`app.protocol.robot.detect`), so
  ROS 1, ROS 2 up to Iron and Jazzy+ robots all work. The camera (:mod:`vehicle_agent.roscamera`)
  shares its connection: one rosbridge connection per robot.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from typing import Any, Final, Protocol

from app.protocol.robot import TURTLESIM, Robot, RobotTypes, detect, pose_of, velocity_message
from app.protocol.ros import AUTO, ROS_SETTINGS, RosSetting
from app.turtlesim.sim import TurtleSim
from vehicle_agent.core.control import Pose
from vehicle_agent.rosbridge_client import (
    CallFailed,
    Publication,
    RosbridgeClient,
    RosbridgeError,
    Subscription,
)

log = logging.getLogger(__name__)

PoseCallback = Callable[[Pose], None]

# How long the spawn step's teleport may take to be answered.
TELEPORT_TIMEOUT_S: Final = 5.0


class RobotLinkError(RuntimeError):
    """The robot could not be reached or refused a request; the message names it and why."""


class RobotLink(Protocol):
    """What the agent needs from its link to the robot."""

    async def start(self, on_pose: PoseCallback) -> None:
        """Connect; ``on_pose`` is then called on the event loop for every pose update."""

    def publish(self, linear: float, angular: float) -> None:
        """Send a velocity command (``cmd_vel``): forward m/s, counter-clockwise rad/s."""

    async def teleport(self, x: float, y: float, theta: float) -> None:
        """Put a turtle at (x, y) facing theta (``teleport_absolute``); raises RobotLinkError."""

    async def close(self) -> None:
        """Disconnect and stop calling ``on_pose``."""

    def renew(self, token: str) -> None:
        """The session's token was renewed: prove the fresh one where the old one was sent."""


class SimLink:
    """An in-process turtlesim stepped by an asyncio task, one fixed tick every 16 ms."""

    def __init__(self, sim: TurtleSim | None = None, name: str = "turtle1") -> None:
        self.sim = sim or TurtleSim()
        self.name = name
        self._task: asyncio.Task[None] | None = None

    async def start(self, on_pose: PoseCallback) -> None:
        """Start ticking; every tick publishes the pose, as turtlesim_node does."""
        self.sim.pose(self.name)  # KeyError now rather than in the tick task
        self._task = asyncio.create_task(self._run(on_pose), name="turtlesim-tick")

    async def _run(self, on_pose: PoseCallback) -> None:
        start = time.monotonic()
        ticks = 0
        while True:
            self.sim.step()
            pose = self.sim.pose(self.name)
            on_pose(Pose(pose.x, pose.y, pose.theta))
            ticks += 1
            delay = start + ticks * self.sim.TICK_S - time.monotonic()
            if delay < -1.0:
                # Far behind (the loop stalled): do not replay a burst of ticks.
                start, ticks = time.monotonic(), 0
            await asyncio.sleep(max(0.0, delay))

    def publish(self, linear: float, angular: float) -> None:
        """Command the simulated turtle."""
        self.sim.cmd_vel(self.name, linear, angular)

    async def teleport(self, x: float, y: float, theta: float) -> None:
        """Teleport the simulated turtle."""
        self.sim.teleport_absolute(self.name, x, y, theta)

    def renew(self, token: str) -> None:
        """Nothing to prove: the simulated turtle is in this process."""

    async def close(self) -> None:
        """Stop ticking."""
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
            self._task = None


class RosbridgeLink:
    """The robot ``robot`` describes (default: turtlesim's turtle1) behind the rosbridge that
    ``client`` connects to. The link owns the connection (:meth:`close` closes it); the camera
    borrows it."""

    def __init__(
        self,
        client: RosbridgeClient,
        ros: RosSetting = AUTO,
        robot: Robot = TURTLESIM,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        if ros not in ROS_SETTINGS:
            raise RobotLinkError(f"--ros must be one of {', '.join(ROS_SETTINGS)}, not {ros!r}")
        self.client = client
        self.robot = robot
        self.setting: RosSetting = ros
        # Known once connected: the types in use and whether the robot named them.
        self.types: RobotTypes | None = None
        # A TwistStamped's stamp: ROS time is the wall clock's seconds since the epoch.
        self.wall_clock = wall_clock
        self._pose: Subscription | None = None
        self._bad_pose_logged = False

    async def start(self, on_pose: PoseCallback) -> None:
        """Connect (unless the camera did), learn the types, advertise the velocity topic and
        subscribe to the pose source."""
        try:
            await self.client.connect()
        except RosbridgeError as exc:
            raise RobotLinkError(str(exc)) from None
        types = self.types = await self._detect()
        robot = self.robot
        self.client.advertise(robot.velocity.topic, types.velocity)

        def received(publication: Publication) -> None:
            read = pose_of(robot.pose.type, publication.msg)
            if read is None:
                if not self._bad_pose_logged:
                    log.warning("%s: a message without a pose; ignored", robot.pose.topic)
                    self._bad_pose_logged = True
                return
            on_pose(Pose(*read))

        self._pose = self.client.subscribe(robot.pose.topic, types.pose, received)
        log.info(
            "driving %s (%s, %s) through rosbridge at %s",
            robot.name,
            robot.velocity.topic,
            robot.pose.topic,
            self.client.url,
        )

    async def _detect(self) -> RobotTypes:
        """Ask rosapi for the pose and velocity types; the setting decides what it cannot."""
        robot = self.robot
        pose, velocity = await asyncio.gather(
            self.client.topic_type(robot.pose.topic), self.client.topic_type(robot.velocity.topic)
        )
        types = detect(robot, pose, velocity, self.setting)
        if types.from_robot:
            log.info("the robot speaks ROS %s: %s, %s", types.flavour, types.pose, types.velocity)
            if self.setting not in (AUTO, types.flavour):
                log.warning(
                    "--ros %s ignored: the robot reports ROS %s types", self.setting, types.flavour
                )
        else:
            log.warning(
                "rosapi did not name %s's type as a %s; using ROS %s names (--ros %s)",
                robot.pose.topic,
                robot.pose.type,
                types.flavour,
                self.setting,
            )
        if types.velocity_kind != robot.velocity.type:
            log.warning(
                "%s is a %s on the robot, not a %s as described: publishing what the robot takes",
                robot.velocity.topic,
                types.velocity_kind,
                robot.velocity.type,
            )
        return types

    def publish(self, linear: float, angular: float) -> None:
        """Publish on the velocity topic in its type (dropped while the connection is down)."""
        types = self.types
        if types is None:
            return
        message: dict[str, Any] = velocity_message(
            types.velocity_kind,
            types.flavour,
            linear,
            angular,
            self.wall_clock(),
            self.robot.velocity.frame_id,
        )
        self.client.publish(self.robot.velocity.topic, message)

    async def teleport(self, x: float, y: float, theta: float) -> None:
        """Call the turtle's ``teleport_absolute`` and wait for the robot's answer."""
        types, service = self.types, self.robot.teleport_service
        if service is None:
            raise RobotLinkError(f"{self.robot.name} is no turtlesim: it has no teleport_absolute")
        if types is None:
            raise RobotLinkError(f"not connected to rosbridge at {self.client.url}")
        try:
            await self.client.call(service, {"x": x, "y": y, "theta": theta}, TELEPORT_TIMEOUT_S)
        except CallFailed as exc:
            raise RobotLinkError(str(exc)) from None

    def renew(self, token: str) -> None:
        """Prove the fresh token on the connection (the camera's too: it is the same one)."""
        self.client.renew(token)

    async def close(self) -> None:
        """Unsubscribe, unadvertise and close the connection."""
        if self._pose is not None:
            self.client.unsubscribe(self._pose)
            self._pose = None
        self.client.unadvertise(self.robot.velocity.topic)
        await self.client.close()
