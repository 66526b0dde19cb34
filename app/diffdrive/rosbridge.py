"""The rosbridge v2 protocol over one room's :class:`~app.diffdrive.sim.ArenaSim`, without I/O.

:class:`DiffDriveHub` is what the protocol's sessions (:mod:`app.rosbridge.protocol`) talk to in
one room: the robot's three topics and rosapi's answers about its graph. ``/cmd_vel`` takes a
``geometry_msgs/Twist`` (and its subscribers get what is published on it); ``/odom`` has a new
``nav_msgs/Odometry`` every tick; the camera topic has the latest frame the owner rendered and
handed over with :meth:`DiffDriveHub.publish_frame` -- :meth:`DiffDriveHub.camera_wanted` says
whether anyone subscribes, so that nothing is rendered for no one. It has no services but
rosapi's.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from typing import Any, Final, Literal

from app.diffdrive import messages
from app.diffdrive.robot import DESCRIPTION
from app.diffdrive.sim import ArenaSim
from app.protocol.ros import RosFlavour
from app.rosbridge.hosted import Versioned
from app.rosbridge.messages import Twist
from app.rosbridge.protocol import (
    MAX_QUEUE_LENGTH,
    Hub,
    ProtocolError,
    parse_payload,
)
from app.rosbridge.rosapi import RosGraph

Json = dict[str, Any]
Leaf = Literal["cmd_vel", "odom", "camera"]

# The robot's topics by what they are, as its description names them (a TurtleBot's names).
assert DESCRIPTION.camera is not None
TOPICS: Final[dict[Leaf, str]] = {
    "cmd_vel": DESCRIPTION.velocity.topic,
    "odom": DESCRIPTION.pose.topic,
    "camera": DESCRIPTION.camera.topic,
}
NODE: Final = "/diffdrive"


class DiffDriveNode:
    """The simulated robot's node on the ROS graph, for rosapi."""

    name = NODE

    def publishes(self, graph: RosGraph) -> dict[str, str]:
        """Topics the node publishes, and their types."""
        t = graph.types
        return {TOPICS["odom"]: t.odometry, TOPICS["camera"]: t.compressed_image}

    def subscribes(self, graph: RosGraph) -> dict[str, str]:
        """Topics the node listens to, and their types."""
        return {TOPICS["cmd_vel"]: graph.types.twist}

    def serves(self, graph: RosGraph) -> dict[str, str]:
        """Services of its own: none."""
        return {}

    def parameters(self, graph: RosGraph) -> dict[str, Any]:
        """Parameters of its own, by their short name: none."""
        return {}

    def parameter_problem(self, name: str, value: object) -> str:
        """Nothing of its own to check."""
        return ""

    def parameter_set(self, name: str, value: object) -> None:
        """Nothing follows from a parameter here."""


class DiffDriveHub(Hub[Leaf]):
    """One room's robot and every session talking to it."""

    def __init__(
        self,
        sim: ArenaSim,
        ros: RosFlavour,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        super().__init__(RosGraph(DiffDriveNode(), ros, wall_clock))
        self.sim = sim
        self._wall_clock = wall_clock
        self._odometry: Json | None = None  # this tick's, made when first asked for
        self._twists: deque[Versioned] = deque(maxlen=MAX_QUEUE_LENGTH)
        self._twist_version = 0
        self._frame: Versioned | None = None
        self.frames = 0

    # -- the protocol's questions ----------------------------------------------------------

    def resolve(self, name: str) -> Leaf:
        """The topic ``name`` (leading slash optional) is; ``ProtocolError`` for any other."""
        absolute = name if name.startswith("/") else f"/{name}"
        for leaf, topic in TOPICS.items():
            if absolute == topic:
                return leaf
        raise ProtocolError(f"unknown topic {name!r}: this robot has {', '.join(TOPICS.values())}")

    def topic_type(self, topic: Leaf) -> str:
        """The topic's type, as this hub's flavour spells it."""
        t = self.types
        return {"cmd_vel": t.twist, "odom": t.odometry, "camera": t.compressed_image}[topic]

    def robot_publishes(self, topic: Leaf) -> bool:
        """Only ``/cmd_vel`` takes clients' messages."""
        return topic != "cmd_vel"

    def publish(self, topic: Leaf, name: str, payload: Json) -> None:
        """A Twist on ``/cmd_vel``: the robot drives it, its subscribers get it."""
        twist = parse_payload(Twist, payload, f"{name} (geometry_msgs/Twist)")
        try:
            self.sim.robot.cmd_vel(twist.linear.x, twist.angular.z)
        except ValueError as exc:  # pydantic let no infinity through; kept for the robot's rule
            raise ProtocolError(f"{name}: {exc}") from None
        self._twist_version += 1
        self._twists.append((self._twist_version, twist.model_dump()))

    def version(self, topic: Leaf) -> int:
        """The topic's current version: a new subscription takes only what comes after it."""
        if topic == "cmd_vel":
            return self._twist_version
        return self.ticks if topic == "odom" else self.frames

    def newer(self, topic: Leaf, seen: int) -> list[Versioned]:
        """The topic's messages newer than version ``seen``, oldest first: of ``/odom`` and the
        camera only the latest (a newer one supersedes them)."""
        if topic == "cmd_vel":
            return [item for item in self._twists if item[0] > seen]
        if topic == "camera":
            return [self._frame] if self._frame is not None and self._frame[0] > seen else []
        if self.ticks <= seen:
            return []
        if self._odometry is None:
            self._odometry = messages.odometry(
                self.types.flavour, self.sim.robot.state(), self._wall_clock(), self.ticks
            )
        return [(self.ticks, self._odometry)]

    def call_service(self, name: str, args: Json) -> Json:
        """This robot serves nothing but rosapi."""
        raise ProtocolError("unknown service")

    # -- the owner's side ------------------------------------------------------------------

    def tick(self, now: float) -> None:
        """Call after each step of the arena: a new odometry message, as of ``now``."""
        super().tick(now)
        self._odometry = None

    def camera_wanted(self) -> bool:
        """Whether any session subscribes to the camera: render only then."""
        return self.subscribed("camera")

    def publish_frame(self, jpeg: bytes, stamp_s: float) -> None:
        """A rendered frame (JPEG bytes, taken at ``stamp_s`` Unix seconds) for the camera's
        subscribers; it supersedes the one before."""
        self.frames += 1
        message = messages.compressed_image(self.types.flavour, jpeg, stamp_s, self.frames)
        self._frame = (self.frames, message)
