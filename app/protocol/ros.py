"""ROS flavours and every ROS type name this project speaks, written once.

Three flavours differ in how a type is spelled on the wire of a rosbridge server:

* ``"1"``  ROS 1 (noetic): ``package/Name`` for messages and services alike.
* ``"2"``  ROS 2 up to Iron: ``package/msg/Name`` and ``package/srv/Name``.
* ``"jazzy"``  ROS 2 Jazzy and later: as ``"2"``, but turtlesim's own interfaces moved from the
  ``turtlesim`` package to ``turtlesim_msgs`` (ros/ros_tutorials#169).

rosbridge for ROS 2 also accepts the short ``package/Name`` spelling of a ROS 2 type; a ROS 1
rosbridge accepts only ``package/Name``. :func:`spellings` says which spellings a server of one
flavour accepts for a type.

The simulator serves one flavour (``autopilot serve --ros``), the agent and the vehicle page
learn a robot's flavour from rosapi ``topic_type`` and fall back to a setting
(:func:`app.protocol.robot.detect`). A robot description names its message types the short way,
``package/Name`` (:func:`spell` gives a flavour's spelling, :func:`canonical` reads one back).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Literal, get_args

RosFlavour = Literal["1", "2", "jazzy"]
ROS_FLAVOURS: Final[tuple[RosFlavour, ...]] = get_args(RosFlavour)
DEFAULT_FLAVOUR: Final[RosFlavour] = "2"
# What a client (vehicle page ``ros=``, agent ``--ros``) may be told: a flavour, or ``auto`` to
# learn it from the robot's rosapi (the default).
RosSetting = Literal["auto", "1", "2", "jazzy"]
ROS_SETTINGS: Final[tuple[RosSetting, ...]] = get_args(RosSetting)
AUTO: Final[RosSetting] = "auto"
# How long a client waits for rosapi's topic_type before using its setting (a robot without
# rosapi fails the call at once; this covers one that never answers).
DETECT_TIMEOUT_S: Final = 3.0

Kind = Literal["msg", "srv"]


def type_name(flavour: RosFlavour, package: str, kind: Kind, name: str) -> str:
    """How ``flavour`` spells the interface ``package``/``name`` (a ``msg`` or a ``srv``)."""
    if flavour == "jazzy" and package == "turtlesim":
        package = "turtlesim_msgs"
    if flavour == "1":
        return f"{package}/{name}"
    return f"{package}/{kind}/{name}"


def spell(flavour: RosFlavour, canonical: str) -> str:
    """How ``flavour`` spells the message type ``canonical`` (``package/Name``)."""
    package, name = canonical.split("/")
    return type_name(flavour, package, "msg", name)


def canonical(spelled: str) -> str | None:
    """The short name ``package/Name`` of a message type in any flavour's spelling
    (``geometry_msgs/msg/Twist``, ``turtlesim_msgs/msg/Pose``), None if it is not one."""
    parts = spelled.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        parts = [parts[0], parts[2]]
    if len(parts) != 2 or not all(parts):
        return None
    package, name = parts
    return f"{'turtlesim' if package == 'turtlesim_msgs' else package}/{name}"


def spellings(flavour: RosFlavour, canonical: str) -> frozenset[str]:
    """Every spelling of the type ``canonical`` (as :class:`RosTypes` gives it) that a rosbridge
    server of ``flavour`` accepts in ``advertise``, ``subscribe`` and ``call_service``."""
    parts = canonical.split("/")
    if flavour == "1" or len(parts) != 3:
        return frozenset({canonical})
    package, _kind, name = parts
    return frozenset({canonical, f"{package}/{name}"})


@dataclass(frozen=True)
class RosTypes:
    """The type names of one flavour, for everything the turtle stack publishes or serves."""

    flavour: RosFlavour
    # turtlesim's topics
    twist: str
    pose: str
    color: str
    # the differential-drive robot's (and a TurtleBot's): its odometry and camera
    odometry: str
    compressed_image: str
    # turtlesim's services
    spawn: str
    kill: str
    empty: str
    teleport_absolute: str
    teleport_relative: str
    set_pen: str
    # the rest of a running graph (rosout, parameter events, rosbridge's client topics)
    log: str
    int32: str
    connected_clients: str
    parameter_event: str
    # rosapi's services are named rosapi/<Name> (ROS 1) or rosapi_msgs/srv/<Name> (ROS 2)
    rosapi_package: str

    def rosapi(self, name: str) -> str:
        """The type of rosapi's service ``name`` (``Topics``, ``GetParam``, ...)."""
        return type_name(self.flavour, self.rosapi_package, "srv", name)


def _types(flavour: RosFlavour) -> RosTypes:
    def msg(package: str, name: str) -> str:
        return type_name(flavour, package, "msg", name)

    def srv(package: str, name: str) -> str:
        return type_name(flavour, package, "srv", name)

    ros1 = flavour == "1"
    return RosTypes(
        flavour=flavour,
        twist=msg("geometry_msgs", "Twist"),
        pose=msg("turtlesim", "Pose"),
        color=msg("turtlesim", "Color"),
        odometry=msg("nav_msgs", "Odometry"),
        compressed_image=msg("sensor_msgs", "CompressedImage"),
        spawn=srv("turtlesim", "Spawn"),
        kill=srv("turtlesim", "Kill"),
        empty=srv("std_srvs", "Empty"),
        teleport_absolute=srv("turtlesim", "TeleportAbsolute"),
        teleport_relative=srv("turtlesim", "TeleportRelative"),
        set_pen=srv("turtlesim", "SetPen"),
        log=msg("rosgraph_msgs", "Log") if ros1 else msg("rcl_interfaces", "Log"),
        int32=msg("std_msgs", "Int32"),
        connected_clients=msg("rosbridge_msgs", "ConnectedClients"),
        parameter_event=msg("rcl_interfaces", "ParameterEvent"),
        rosapi_package="rosapi" if ros1 else "rosapi_msgs",
    )


TYPES: Final[dict[RosFlavour, RosTypes]] = {flavour: _types(flavour) for flavour in ROS_FLAVOURS}


@dataclass(frozen=True)
class RosConfig:
    """What the vehicle page needs to pick its type names, for its embedded config."""

    default: RosFlavour
    detect_timeout_s: float
    settings: tuple[RosSetting, ...]
    types: dict[RosFlavour, RosTypes]


ROS_CONFIG: Final = RosConfig(DEFAULT_FLAVOUR, DETECT_TIMEOUT_S, ROS_SETTINGS, TYPES)
