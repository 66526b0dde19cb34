"""Turtle backends: where the agent's Twists go and where its pose feedback comes from.

* :class:`SimTurtle` -- an in-process :class:`app.turtlesim.sim.TurtleSim` stepped by an asyncio
  task on turtlesim's fixed 16 ms tick (the agent's default: no server, no ROS).
* :class:`RosbridgeTurtle` -- any rosbridge v2 server through roslibpy: this project's
  ``/rosbridge`` endpoint or a real robot's ``rosbridge_server``, driving the robot a
  description names (:mod:`app.protocol.robot`: its velocity topic and type, its pose source).
  The types are learnt from the robot's rosapi ``topic_type``, falling back to the ``--ros``
  setting (:func:`app.protocol.robot.detect`), so ROS 1, ROS 2 up to Iron and Jazzy+ robots
  all work.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Protocol
from urllib.parse import urlsplit

import roslibpy
from autobahn.twisted.websocket import connectWS
from twisted.internet import error as twisted_error
from twisted.internet import reactor
from twisted.internet import ssl as twisted_ssl

from app.protocol.robot import TURTLESIM, Robot, RobotTypes, detect, pose_of, velocity_message
from app.protocol.ros import AUTO, DETECT_TIMEOUT_S, ROS_SETTINGS, TYPES, RosSetting
from app.turtlesim.sim import TurtleSim
from vehicle_agent.control import Pose

log = logging.getLogger(__name__)

PoseCallback = Callable[[Pose], None]

CONNECT_TIMEOUT_S = 5.0


class TurtleError(RuntimeError):
    """A turtle backend could not be reached; the message names it and the problem."""


class Turtle(Protocol):
    """What the agent needs from a turtle."""

    async def start(self, on_pose: PoseCallback) -> None:
        """Connect; ``on_pose`` is then called on the event loop for every pose update."""

    def publish(self, linear: float, angular: float) -> None:
        """Send a velocity command (``cmd_vel``): forward m/s, counter-clockwise rad/s."""

    async def teleport(self, x: float, y: float, theta: float) -> None:
        """Put the turtle at (x, y) facing theta (``teleport_absolute``); raises TurtleError."""

    async def close(self) -> None:
        """Disconnect and stop calling ``on_pose``."""

    def renew(self, token: str) -> None:
        """The session's token was renewed: prove the fresh one where the old one was sent."""


class SimTurtle:
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


class RosbridgeTurtle:
    """A robot behind a rosbridge v2 server, driven with roslibpy: the robot ``robot``
    describes (default: turtlesim's turtle1).

    roslibpy runs its own network thread; pose callbacks are handed to the asyncio loop.
    """

    def __init__(
        self,
        url: str,
        ros: RosSetting = AUTO,
        robot: Robot = TURTLESIM,
        token: str | None = None,
        ca_file: Path | None = None,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        if not url.startswith(("ws://", "wss://")):
            raise TurtleError(f"rosbridge URL must start with ws:// or wss://, not {url!r}")
        if ros not in ROS_SETTINGS:
            raise TurtleError(f"--ros must be one of {', '.join(ROS_SETTINGS)}, not {ros!r}")
        self.url = url
        self.robot = robot
        self.setting: RosSetting = ros
        # Known once connected: the types in use and whether the robot named them.
        self.types: RobotTypes | None = None
        # Sent as a bearer header on the handshake; the server's /rosbridge checks it.
        self.headers = {"Authorization": f"Bearer {token}"} if token else None
        self.ca_file = ca_file
        # A TwistStamped's stamp: ROS time is the wall clock's seconds since the epoch.
        self.wall_clock = wall_clock
        self._ros: roslibpy.Ros | None = None
        self._cmd_vel: roslibpy.Topic | None = None
        self._pose: roslibpy.Topic | None = None
        self._bad_pose_logged = False

    async def start(self, on_pose: PoseCallback) -> None:
        """Connect, advertise the velocity topic and subscribe to the pose source."""
        loop = asyncio.get_running_loop()
        if self.url.startswith("wss:"):
            ros: roslibpy.Ros = _VerifiedRos(self.url, self.headers, _tls_options(self))
        else:
            ros = roslibpy.Ros(host=self.url, headers=self.headers, transport="twisted")
        reason = await _connect(ros, loop)
        if reason is not None:
            # Twisted would keep retrying in the background; we give up and say so.
            reactor.callFromThread(ros.factory.stopTrying)
            raise TurtleError(f"cannot connect to rosbridge at {self.url}: {reason}")
        self._ros = ros
        ros.on("close", lambda *_: log.warning("rosbridge connection to %s lost", self.url))
        types = self.types = await self._detect(ros)
        robot = self.robot
        self._cmd_vel = roslibpy.Topic(ros, robot.velocity.topic, types.velocity)
        self._cmd_vel.advertise()

        def received(message: dict[str, Any]) -> None:
            read = pose_of(robot.pose.type, message)
            if read is None:
                if not self._bad_pose_logged:
                    log.warning("%s: a message without a pose; ignored", robot.pose.topic)
                    self._bad_pose_logged = True
                return
            loop.call_soon_threadsafe(on_pose, Pose(*read))

        self._pose = roslibpy.Topic(ros, robot.pose.topic, types.pose)
        self._pose.subscribe(received)
        log.info(
            "driving %s (%s, %s) through rosbridge at %s",
            robot.name,
            robot.velocity.topic,
            robot.pose.topic,
            self.url,
        )

    async def _detect(self, ros: roslibpy.Ros) -> RobotTypes:
        """Ask rosapi for the pose and velocity types; the setting decides what it cannot."""
        robot = self.robot
        pose, velocity = [
            await asyncio.to_thread(self._topic_type, ros, topic)
            for topic in (robot.pose.topic, robot.velocity.topic)
        ]
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

    def _topic_type(self, ros: roslibpy.Ros, topic: str) -> str | None:
        """rosapi's ``topic_type`` for ``topic``; None when rosapi is missing or silent."""
        service = roslibpy.Service(ros, "/rosapi/topic_type", "rosapi/TopicType")
        try:
            reply = service.call(
                roslibpy.ServiceRequest({"topic": topic}), timeout=DETECT_TIMEOUT_S
            )
        except roslibpy.core.ServiceException as exc:
            log.info("rosapi topic_type %s failed: %s", topic, exc)
            return None
        except TimeoutError:  # roslibpy's RosTimeoutError
            log.info("rosapi topic_type %s: no answer within %g s", topic, DETECT_TIMEOUT_S)
            return None
        kind = reply.get("type") if isinstance(reply, Mapping) else None  # a UserDict
        return kind if isinstance(kind, str) and kind else None

    def publish(self, linear: float, angular: float) -> None:
        """Publish on the velocity topic in its type (roslibpy hands it to its network thread)."""
        types = self.types
        if self._cmd_vel is None or types is None:
            return
        message = velocity_message(
            types.velocity_kind,
            types.flavour,
            linear,
            angular,
            self.wall_clock(),
            self.robot.velocity.frame_id,
        )
        self._cmd_vel.publish(roslibpy.Message(message))

    async def teleport(self, x: float, y: float, theta: float) -> None:
        """Call the turtle's ``teleport_absolute`` and wait for the robot's answer."""
        ros, types, service_name = self._ros, self.types, self.robot.teleport_service
        if service_name is None:
            raise TurtleError(f"{self.robot.name} is no turtlesim: it has no teleport_absolute")
        if ros is None or types is None:
            raise TurtleError(f"not connected to rosbridge at {self.url}")
        loop = asyncio.get_running_loop()
        answered: asyncio.Future[str | None] = loop.create_future()

        def settle(error: str | None) -> None:
            if not answered.done():
                answered.set_result(error)

        teleport = TYPES[types.flavour].teleport_absolute
        service = roslibpy.Service(ros, service_name, teleport)
        service.call(
            roslibpy.ServiceRequest({"x": x, "y": y, "theta": theta}),
            lambda _response: loop.call_soon_threadsafe(settle, None),
            lambda error: loop.call_soon_threadsafe(settle, str(error)),
        )
        try:
            error = await asyncio.wait_for(answered, CONNECT_TIMEOUT_S)
        except TimeoutError:
            error = f"no answer within {CONNECT_TIMEOUT_S:g} s"
        if error is not None:
            raise TurtleError(f"{service_name} failed: {error}")

    def renew(self, token: str) -> None:
        """Send the rosbridge ``auth`` op with the fresh token, if this rosbridge was given one
        (the server's own ``/rosbridge`` ends a session whose token expires)."""
        if self.headers is None:
            return
        self.headers = {"Authorization": f"Bearer {token}"}
        if self._ros is not None:
            self._ros.send_on_ready(roslibpy.Message({"op": "auth", "token": token}))
            # A reconnection (roslibpy's own, after a drop) shakes hands with the fresh one.
            self._ros.factory.headers = dict(self.headers)

    async def close(self) -> None:
        """Unsubscribe and disconnect (the roslibpy thread itself lives on with the process)."""
        ros, self._ros = self._ros, None
        if ros is None:
            return
        if self._pose is not None:
            self._pose.unsubscribe()
        if self._cmd_vel is not None:
            self._cmd_vel.unadvertise()
        await asyncio.to_thread(ros.close)


def _tls_options(turtle: RosbridgeTurtle) -> Any:
    """Twisted TLS options that check the rosbridge's certificate and name: against
    ``turtle.ca_file`` if given, else the system's trusted CAs."""
    host = urlsplit(turtle.url).hostname or ""
    if turtle.ca_file is None:
        return twisted_ssl.optionsForClientTLS(host)
    try:
        root = twisted_ssl.Certificate.loadPEM(turtle.ca_file.read_bytes())
    except OSError as exc:
        raise TurtleError(f"cannot read --ca-file {turtle.ca_file}: {exc}") from exc
    return twisted_ssl.optionsForClientTLS(host, trustRoot=root)


async def _connect(ros: roslibpy.Ros, loop: asyncio.AbstractEventLoop) -> str | None:
    """Start ``ros``'s connection; None once it is ready, else why not: the first failed attempt
    (a refused port says so at once instead of after the whole timeout; one that failed before
    this hook was in place is caught on twisted's retry) or the timeout."""
    outcome: asyncio.Future[str | None] = loop.create_future()

    def settle(reason: str | None) -> None:
        if not outcome.done():
            outcome.set_result(reason)

    factory = ros.factory
    retry = factory.clientConnectionFailed

    def failed(connector: Any, reason: Any) -> None:
        # Twisted's Failure: its value is the error, e.g. ConnectionRefusedError.
        loop.call_soon_threadsafe(settle, _failure_text(reason.value))
        retry(connector, reason)

    factory.clientConnectionFailed = failed
    factory.on_ready(lambda _proto: loop.call_soon_threadsafe(settle, None))
    # Ros() queued its connection on the reactor thread; this starts that thread (once).
    factory.manager.run()
    try:
        return await asyncio.wait_for(outcome, CONNECT_TIMEOUT_S)
    except TimeoutError:
        return f"no answer within {CONNECT_TIMEOUT_S:g} s"


def _failure_text(error: BaseException) -> str:
    if isinstance(error, twisted_error.ConnectionRefusedError):
        return "connection refused (is rosbridge running on that port?)"
    return str(error) or type(error).__name__


class _VerifiedRos(roslibpy.Ros):  # type: ignore[misc]
    """roslibpy's twisted transport connects wss:// without checking the certificate at all
    (autobahn's default ``ClientContextFactory``); this one connects with ``options`` instead."""

    def __init__(self, url: str, headers: dict[str, str] | None, options: Any) -> None:
        self._tls = options
        super().__init__(host=url, headers=headers, transport="twisted")

    def connect(self) -> None:
        factory = self.factory

        def connect_verified() -> None:
            factory.connector = connectWS(factory, contextFactory=self._tls)

        # Ros.connect() queues factory._connect on the reactor thread; this replaces it.
        factory._connect = connect_verified
        super().connect()
