"""A robot's description: the topics it speaks, its camera and its limits (docs/robots.md).

The agent (``autopilot vehicle --robot NAME|FILE``) and the vehicle page (``?robot=NAME``) drive
the robot that a :class:`Robot` describes: they publish on its velocity topic in its type
(``geometry_msgs/Twist``, or ``geometry_msgs/TwistStamped`` with a header), read its pose from
its pose source (``turtlesim/Pose``, or ``nav_msgs/Odometry`` with the heading from the
quaternion), and every command they publish is clamped to its :class:`Limits` and ramped within
its accelerations (the pilot's limiter). Three presets (:data:`PRESETS`); any other robot is a
description file, which :mod:`app.robot_file` reads and :func:`parse` checks here, refusing it in
one line naming the key and the problem.

What only a turtlesim has stays with the turtlesim: the spawn step (``teleport_absolute``
beside its pose topic) and the 11 m terrain whose walls the follow law keeps clear of
(:attr:`Robot.turtlesim`).

Types are named the short way, ``package/Name``; a robot's rosapi still decides the flavour's
spelling, and the velocity type when it names one (:func:`detect`).
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final, Literal, cast, get_args

from app.protocol.camera import CAMERA_TYPES, CameraType
from app.protocol.ros import AUTO, DEFAULT_FLAVOUR, ROS_FLAVOURS, RosFlavour, RosSetting, spell
from app.protocol.ros import canonical as canonical_type

VelocityType = Literal["geometry_msgs/Twist", "geometry_msgs/TwistStamped"]
PoseType = Literal["turtlesim/Pose", "nav_msgs/Odometry"]
VELOCITY_TYPES: Final[tuple[VelocityType, ...]] = get_args(VelocityType)
POSE_TYPES: Final[tuple[PoseType, ...]] = get_args(PoseType)
TWIST: Final[VelocityType] = "geometry_msgs/Twist"
TWIST_STAMPED: Final[VelocityType] = "geometry_msgs/TwistStamped"
TURTLESIM_POSE: Final[PoseType] = "turtlesim/Pose"
ODOMETRY: Final[PoseType] = "nav_msgs/Odometry"

# A TwistStamped's header.frame_id when the description names none: the robot's body frame.
DEFAULT_FRAME_ID: Final = "base_link"


@dataclass(frozen=True)
class Velocity:
    """Where velocity commands go, and in which type."""

    topic: str
    type: VelocityType
    # A TwistStamped's header.frame_id ("" for a Twist, which has no header).
    frame_id: str


@dataclass(frozen=True)
class PoseSource:
    """Where the robot's pose comes from: a ``turtlesim/Pose`` or ``nav_msgs/Odometry`` topic."""

    topic: str
    type: PoseType


@dataclass(frozen=True)
class Camera:
    """The robot's own camera: its image topic, the topic's type and the horizontal field of
    view (degrees) that turns a pixel into a bearing."""

    topic: str
    type: CameraType
    hfov_deg: float


@dataclass(frozen=True)
class Limits:
    """What the robot can do: top speeds and the accelerations every command is ramped within.

    Speeds are m/s and rad/s, accelerations m/s² and rad/s²; ``math.inf`` is "no limit".
    """

    max_linear: float
    max_angular: float
    linear_accel: float
    angular_accel: float


@dataclass(frozen=True)
class Robot:
    """One robot's description."""

    name: str
    velocity: Velocity
    pose: PoseSource
    # None: the robot has no camera topic (its video comes from elsewhere).
    camera: Camera | None
    limits: Limits

    @property
    def turtlesim(self) -> bool:
        """True for a turtlesim turtle: it has the spawn step and the 11 m terrain's walls.
        Only turtlesim publishes ``turtlesim/Pose``, so the pose source says it."""
        return self.pose.type == TURTLESIM_POSE

    @property
    def teleport_service(self) -> str | None:
        """The turtle's ``teleport_absolute`` (beside its pose topic) for the spawn step; None
        for any robot but a turtlesim."""
        if not self.turtlesim:
            return None
        namespace = self.pose.topic.rsplit("/", 1)[0]
        return f"{namespace}/teleport_absolute"


# The turtle as it always was: turtlesim's own topics, and limits no lower than what the
# profiles ever command (the follow law's 4 m/s and 5 rad/s; turtlesim applies a command at
# once), so that describing it changes nothing it does.
TURTLESIM: Final = Robot(
    name="turtlesim",
    velocity=Velocity("/turtle1/cmd_vel", TWIST, ""),
    pose=PoseSource("/turtle1/pose", TURTLESIM_POSE),
    camera=None,
    limits=Limits(max_linear=4.0, max_angular=5.0, linear_accel=math.inf, angular_accel=math.inf),
)

PRESETS: Final[dict[str, Robot]] = {
    "turtlesim": TURTLESIM,
    # The differential-drive robot with an onboard camera that the simulator plays
    # (app/diffdrive): it speaks these topics, renders the camera with this field of view and
    # caps the robot's speeds at these.
    "diffdrive": Robot(
        name="diffdrive",
        velocity=Velocity("/cmd_vel", TWIST, ""),
        pose=PoseSource("/odom", ODOMETRY),
        camera=Camera("/camera/image/compressed", "sensor_msgs/CompressedImage", 60.0),
        limits=Limits(max_linear=1.0, max_angular=3.0, linear_accel=2.0, angular_accel=6.0),
    ),
    # TurtleBot3 Burger (sources in docs/robots.md): speeds from ROBOTIS's e-Manual
    # specifications; accelerations from turtlebot3_navigation2's burger.yaml (acc_lim_x,
    # acc_lim_theta); the camera topic from turtlebot3_bringup's camera launch, its field of
    # view from the Raspberry Pi camera's calibration there (2·atan(320 / 495.513) at 640 px).
    "turtlebot3": Robot(
        name="turtlebot3",
        velocity=Velocity("/cmd_vel", TWIST, ""),
        pose=PoseSource("/odom", ODOMETRY),
        camera=Camera("/camera/image_raw/compressed", "sensor_msgs/CompressedImage", 65.7),
        limits=Limits(max_linear=0.22, max_angular=2.84, linear_accel=2.5, angular_accel=3.2),
    ),
}
DEFAULT_ROBOT: Final = "turtlesim"


# --- reading a description ---------------------------------------------------------------


class RobotError(ValueError):
    """A robot that cannot be described: one line naming the key and what is wrong."""


# A description's text goes into logs and ROS messages: a name or a frame id is at most this
# long, and a topic (a ROS graph name) at most that, so that no file can flood a log line.
MAX_NAME_CHARS: Final = 64
MAX_TOPIC_CHARS: Final = 256
# How much of a bad value an error shows, escaped (a control character is never shown raw).
_SHOWN_CHARS: Final = 40


# A ROS graph resource name (ROS 2's rules, which ROS 1's accept): segments of letters, digits
# and underscores, not starting with a digit, separated by single slashes.
_TOPIC_RE = re.compile(r"/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*\Z")

# Every key of a description file, by table; the values say what each holds.
_KEYS: Final[dict[str, tuple[str, ...]]] = {
    "": ("name", "velocity", "pose", "camera", "limits"),
    "velocity": ("topic", "type", "frame_id"),
    "pose": ("topic", "type"),
    "camera": ("topic", "type", "hfov_deg"),
    "limits": ("max_linear", "max_angular", "linear_accel", "angular_accel"),
}
_UNITS: Final = {
    "max_linear": "m/s",
    "max_angular": "rad/s",
    "linear_accel": "m/s²",
    "angular_accel": "rad/s²",
}


class _Reader:
    """Reads one table of a description, naming each key by its dotted path in errors."""

    def __init__(self, data: Mapping[str, Any], table: str) -> None:
        self.data = data
        self.table = table
        for key in data:
            if key not in _KEYS[table]:
                known = ", ".join(_KEYS[table])
                unknown = key if _BARE_KEY_RE.match(key) else _shown(key)
                raise RobotError(f"{self.path(unknown)}: unknown key (this table has {known})")

    def path(self, key: str) -> str:
        return f"{self.table}.{key}" if self.table else key

    def has(self, key: str) -> bool:
        return key in self.data

    def table_of(self, key: str) -> _Reader:
        value = self.data.get(key)
        if value is None:
            raise RobotError(f"{self.path(key)}: missing (a [{key}] table)")
        if not isinstance(value, dict):
            raise RobotError(f"{self.path(key)}: must be a table ([{key}]), not {_kind(value)}")
        return _Reader(value, key)

    def text(self, key: str, default: str | None = None, limit: int = MAX_TOPIC_CHARS) -> str:
        value = self.data.get(key, default)
        if value is None:
            raise RobotError(f"{self.path(key)}: missing")
        if not isinstance(value, str):
            raise RobotError(f"{self.path(key)}: must be a string, not {_kind(value)}")
        return _checked_text(self.path(key), value, limit)

    def topic(self) -> str:
        topic = self.text("topic")
        if not _TOPIC_RE.match(topic):
            raise RobotError(
                f"{self.path('topic')}: not a ROS topic name: {_shown(topic)} (letters, digits, "
                "underscores and single slashes, e.g. /cmd_vel)"
            )
        return topic if topic.startswith("/") else f"/{topic}"

    def message_type(self, choices: tuple[str, ...]) -> str:
        spelled = self.text("type")
        found = canonical_type(spelled)
        if found not in choices:
            raise RobotError(
                f"{self.path('type')}: unknown message type {_shown(spelled)} (one of "
                f"{', '.join(choices)})"
            )
        return found

    def number(self, key: str, what: str, valid: Callable[[float], bool]) -> float:
        value = self.data.get(key)
        if value is None:
            raise RobotError(f"{self.path(key)}: missing")
        # TOML's booleans are not numbers, though Python's bool is an int.
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise RobotError(f"{self.path(key)}: must be a number, not {_kind(value)}")
        # TOML's integers have no bound; a float has (float() of a longer one overflows).
        if isinstance(value, int) and abs(value) > sys.float_info.max:
            raise RobotError(
                f"{self.path(key)}: must be a number within the float range (±"
                f"{sys.float_info.max:.4g}), not {_kind(value)}"
            )
        if math.isnan(value) or not valid(float(value)):
            raise RobotError(f"{self.path(key)}: must be {what}, not {value}")
        return float(value)


# A key shown as it is written: TOML's bare keys (anything else is quoted, escaped).
_BARE_KEY_RE = re.compile(r"[A-Za-z0-9_-]{1,64}\Z")


def _shown(text: str) -> str:
    """``text`` quoted and escaped for an error line, cut to its first characters."""
    if len(text) <= _SHOWN_CHARS:
        return repr(text)
    return f"{text[:_SHOWN_CHARS]!r}... ({len(text)} characters)"


def _checked_text(path: str, text: str, limit: int) -> str:
    """``text`` if it is at most ``limit`` characters, all printable; else :class:`RobotError`."""
    if len(text) > limit:
        raise RobotError(f"{path}: at most {limit} characters, not {len(text)}")
    if not text.isprintable():
        raise RobotError(f"{path}: must not hold control characters or line breaks: {_shown(text)}")
    return text


def _kind(value: object) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, str):
        return f"the string {_shown(value)}"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, list):
        return "an array"
    if isinstance(value, int) and abs(value) > 10**_SHOWN_CHARS:
        return f"an integer of about {int(math.log10(abs(value))) + 1} digits"
    return _shown(str(value))


def parse(data: Mapping[str, Any], default_name: str) -> Robot:
    """The robot that ``data`` (a parsed description file) describes; :class:`RobotError`
    naming the first key that is wrong. ``default_name`` names a robot whose file has no
    ``name``."""
    top = _Reader(data, "")
    name = top.text("name", default_name, MAX_NAME_CHARS).strip()
    if not name:
        raise RobotError("name: must not be empty")
    velocity_table = top.table_of("velocity")
    velocity_type = cast(VelocityType, velocity_table.message_type(VELOCITY_TYPES))
    velocity_topic = velocity_table.topic()
    if velocity_type == TWIST_STAMPED:
        frame_id = velocity_table.text("frame_id", DEFAULT_FRAME_ID, MAX_NAME_CHARS)
    elif velocity_table.has("frame_id"):
        raise RobotError(f"velocity.frame_id: only a {TWIST_STAMPED} has a header to put it in")
    else:
        frame_id = ""
    pose_table = top.table_of("pose")
    pose = PoseSource(
        topic=pose_table.topic(), type=cast(PoseType, pose_table.message_type(POSE_TYPES))
    )
    camera = None
    if top.has("camera"):
        camera_table = top.table_of("camera")
        camera = Camera(
            topic=camera_table.topic(),
            type=cast(CameraType, camera_table.message_type(CAMERA_TYPES)),
            hfov_deg=camera_table.number(
                "hfov_deg", "degrees above 0 and below 180", lambda v: 0.0 < v < 180.0
            ),
        )
    limits_table = top.table_of("limits")

    def limit(key: str, *, speed: bool) -> float:
        unit = _UNITS[key]
        # A top speed of 0 is a robot that never moves that way (a turret that only turns);
        # an acceleration of 0 would never let it start.
        if speed:
            return limits_table.number(key, f"a number >= 0 ({unit})", lambda v: v >= 0.0)
        return limits_table.number(key, f"a number > 0 ({unit})", lambda v: v > 0.0)

    limits = Limits(
        max_linear=limit("max_linear", speed=True),
        max_angular=limit("max_angular", speed=True),
        linear_accel=limit("linear_accel", speed=False),
        angular_accel=limit("angular_accel", speed=False),
    )
    return Robot(name, Velocity(velocity_topic, velocity_type, frame_id), pose, camera, limits)


# --- the robot's messages ----------------------------------------------------------------


@dataclass(frozen=True)
class RobotTypes:
    """The type names a client uses on one robot, and where they came from."""

    flavour: RosFlavour
    # The pose topic's type, spelled as the flavour spells it.
    pose: str
    # The velocity topic's type as it is published, and which of the two it is.
    velocity: str
    velocity_kind: VelocityType
    # True when the robot's rosapi named the pose type (so the flavour); False: the setting.
    from_robot: bool


@dataclass(frozen=True)
class TypeTable:
    """A robot's type names in every flavour, for the detection both vehicles make: the page
    gets this through its embedded config, the agent computes it here."""

    # flavour -> the pose topic's type as that flavour spells it
    pose: dict[RosFlavour, str]
    # flavour -> the described velocity type as that flavour spells it
    velocity: dict[RosFlavour, str]
    # any spelling of Twist or TwistStamped -> which of the two it is
    velocity_kinds: dict[str, VelocityType]


def type_table(robot: Robot) -> TypeTable:
    """The type names of ``robot`` in every flavour."""
    kinds: dict[str, VelocityType] = {}
    for kind in VELOCITY_TYPES:
        kinds[kind] = kind
        for flavour in ROS_FLAVOURS:
            kinds[spell(flavour, kind)] = kind
    return TypeTable(
        pose={f: spell(f, robot.pose.type) for f in ROS_FLAVOURS},
        velocity={f: spell(f, robot.velocity.type) for f in ROS_FLAVOURS},
        velocity_kinds=kinds,
    )


def detect(
    robot: Robot, pose_reported: str | None, velocity_reported: str | None, setting: RosSetting
) -> RobotTypes:
    """The types to use on ``robot``, from what its rosapi ``topic_type`` answered for its pose
    and velocity topics (None: no answer), falling back to ``setting`` (``auto``: the default
    flavour).

    The flavour is the one whose spelling of the pose type the robot reported. A reported
    velocity type that is a Twist or a TwistStamped is used as reported, even if the description
    says the other: the robot's graph is the truth, and a command in any other type would not
    reach it. (``vehicle.js`` makes the same choice from the same :class:`TypeTable`.)
    """
    table = type_table(robot)
    reported = next((f for f, spelled in table.pose.items() if spelled == pose_reported), None)
    flavour: RosFlavour
    if reported is not None:
        flavour = reported
    elif setting == AUTO:
        flavour = DEFAULT_FLAVOUR
    else:
        flavour = cast(RosFlavour, setting)  # every setting but auto is a flavour
    kind = table.velocity_kinds.get(velocity_reported or "")
    if kind is not None and velocity_reported:
        velocity = velocity_reported
    else:
        kind, velocity = robot.velocity.type, table.velocity[flavour]
    return RobotTypes(flavour, table.pose[flavour], velocity, kind, reported is not None)


def twist(linear: float, angular: float) -> dict[str, Any]:
    """A ``geometry_msgs/Twist`` as JSON: ``linear`` (m/s) ahead, ``angular`` (rad/s)
    counter-clockwise."""
    return {
        "linear": {"x": linear, "y": 0.0, "z": 0.0},
        "angular": {"x": 0.0, "y": 0.0, "z": angular},
    }


def velocity_message(
    kind: VelocityType,
    flavour: RosFlavour,
    linear: float,
    angular: float,
    stamp_s: float,
    frame_id: str,
) -> dict[str, Any]:
    """A velocity command as rosbridge JSON: a ``Twist``, or a ``TwistStamped`` stamped
    ``stamp_s`` (seconds since the epoch) in ``frame_id``, its time as ``flavour`` spells it
    (``secs``/``nsecs`` in ROS 1, ``sec``/``nanosec`` in ROS 2). ``robot.js`` has the twin."""
    if kind == TWIST:
        return twist(linear, angular)
    seconds = math.floor(stamp_s)
    nanoseconds = min(999_999_999, round((stamp_s - seconds) * 1e9))
    stamp = (
        {"secs": seconds, "nsecs": nanoseconds}
        if flavour == "1"
        else {"sec": seconds, "nanosec": nanoseconds}
    )
    return {"header": {"stamp": stamp, "frame_id": frame_id}, "twist": twist(linear, angular)}


def yaw_of(x: float, y: float, z: float, w: float) -> float | None:
    """The heading (rotation about z, in (−π, π]) of the quaternion (x, y, z, w), which need not
    be normalised; None for one with no heading (zero, or not finite).

    Both arguments of the atan2 scale with the quaternion's squared norm, so its length does not
    matter (the ``1 − 2(y² + z²)`` form assumes a unit quaternion). ``robot.js`` has the twin.
    """
    sine = 2.0 * (w * z + x * y)
    cosine = w * w + x * x - y * y - z * z
    if not (math.isfinite(sine) and math.isfinite(cosine)) or (sine == 0.0 and cosine == 0.0):
        return None
    yaw = math.atan2(sine, cosine)
    # atan2 gives [−π, π]; the project's angles are (−π, π] (app/protocol/angles.py).
    return math.pi if yaw == -math.pi else yaw


def pose_of(kind: PoseType, message: Mapping[str, Any]) -> tuple[float, float, float] | None:
    """(x, y, heading) from a pose message of ``kind``: a ``turtlesim/Pose``'s x, y and theta,
    an ``Odometry``'s position and the yaw of its orientation; None for a message without
    them. ``robot.js`` has the twin."""
    try:
        if kind == TURTLESIM_POSE:
            x, y, theta = (_number(message[key]) for key in ("x", "y", "theta"))
        else:
            pose = message["pose"]["pose"]
            x, y = _number(pose["position"]["x"]), _number(pose["position"]["y"])
            q = pose["orientation"]
            yaw = yaw_of(*(_number(q[key]) for key in ("x", "y", "z", "w")))
            if yaw is None:
                return None
            theta = yaw
    except (KeyError, TypeError):
        return None
    return x, y, theta


def _number(value: object) -> float:
    """A JSON number as a float; TypeError for anything else (a bool, a string)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"not a number: {value!r}")
    return float(value)
