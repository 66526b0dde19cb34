"""What rosbridge_suite's ``rosapi`` node answers about a robot running turtlesim, without I/O.

:class:`RosGraph` describes the ROS graph a real robot of one flavour shows with
``turtlesim_node``, ``rosbridge_websocket`` and ``rosapi`` running: its topics (``/rosout``
included), services, nodes and parameters (turtlesim's ``background_r/g/b``, 69, 86, 255). It
answers the rosapi calls that Lichtblick/Foxglove, roslib.js and roslibpy make, in the request
and response shapes of that flavour's rosapi (``rosapi/*`` in ROS 1, ``rosapi_msgs/srv/*`` in
ROS 2): ``GetTime`` is ``{secs, nsecs}`` in ROS 1 and ``{sec, nanosec}`` in ROS 2, ``GetParam``
and ``SetParam`` add ``successful``/``reason`` in ROS 2, parameter names are ``/node/param`` in
ROS 1 and ``/node:param`` in ROS 2.

Listed but not simulated: the ``color_sensor`` topics, ``/rosout``, ``/parameter_events`` and
rosbridge's client topics exist on the real graph and are reported, but nothing is published on
them; the nodes' logger and parameter services are left out of the lists.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, StrictStr, ValidationError

from app.protocol.errors import describe
from app.protocol.ros import TYPES, RosFlavour, RosTypes
from app.turtlesim.sim import TurtleSim

Json = dict[str, Any]

TURTLESIM_NODE = "/turtlesim"
# turtlesim's own services: global, then per turtle (/<turtle>/<name>).
GLOBAL_SERVICES = ("clear", "kill", "reset", "spawn")
TURTLE_SERVICES = ("set_pen", "teleport_absolute", "teleport_relative")
# The topics every turtle has, by leaf name.
TURTLE_TOPICS = ("cmd_vel", "color_sensor", "pose")
# turtlesim's default background (turtle_frame's DEFAULT_BG_R/G/B).
BACKGROUND = {"background_r": 69, "background_g": 86, "background_b": 255}

# rosapi service name -> its interface name (rosapi/<Name> or rosapi_msgs/srv/<Name>).
ROSAPI_SERVICES = {
    "topics": "Topics",
    "topics_and_raw_types": "TopicsAndRawTypes",
    "topic_type": "TopicType",
    "services": "Services",
    "service_type": "ServiceType",
    "nodes": "Nodes",
    "node_details": "NodeDetails",
    "get_param": "GetParam",
    "set_param": "SetParam",
    "get_param_names": "GetParamNames",
    "get_time": "GetTime",
}
# The rosapi services that change nothing: they read the graph, the parameters or the clock.
ROSAPI_READS = (
    "topics",
    "topics_and_raw_types",
    "topic_type",
    "services",
    "service_type",
    "nodes",
    "node_details",
    "get_param",
    "get_param_names",
    "get_time",
)
assert set(ROSAPI_READS) < set(ROSAPI_SERVICES), "reads are rosapi services, and not all of them"

# Message definitions as rosapi's typedefs_full_text gives them: the type's own fields, then
# each type it uses after a separator line and "MSG: <type>".
_SEPARATOR = "=" * 80
_DEFINITIONS: dict[str, str] = {
    "geometry_msgs/Twist": "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "turtlesim/Pose": (
        "float32 x\nfloat32 y\nfloat32 theta\n\nfloat32 linear_velocity\nfloat32 angular_velocity"
    ),
    "turtlesim/Color": "uint8 r\nuint8 g\nuint8 b",
    "std_msgs/Int32": "int32 data",
    "std_msgs/Header": "uint32 seq\ntime stamp\nstring frame_id",
    "rosbridge_msgs/ConnectedClients": "rosbridge_msgs/ConnectedClient[] clients",
    "rosbridge_msgs/ConnectedClient": "string ip_address\ntime connection_time",
    "rosgraph_msgs/Log": (
        "byte DEBUG=1\nbyte INFO=2\nbyte WARN=4\nbyte ERROR=8\nbyte FATAL=16\n"
        "std_msgs/Header header\nbyte level\nstring name\nstring msg\nstring file\n"
        "string function\nuint32 line\nstring[] topics"
    ),
    "rcl_interfaces/Log": (
        "byte DEBUG=10\nbyte INFO=20\nbyte WARN=30\nbyte ERROR=40\nbyte FATAL=50\n"
        "builtin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\n"
        "string function\nuint32 line"
    ),
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec",
    "rcl_interfaces/ParameterEvent": (
        "builtin_interfaces/Time stamp\nstring node\n"
        "rcl_interfaces/Parameter[] new_parameters\n"
        "rcl_interfaces/Parameter[] changed_parameters\n"
        "rcl_interfaces/Parameter[] deleted_parameters"
    ),
    "rcl_interfaces/Parameter": "string name\nrcl_interfaces/ParameterValue value",
    "sensor_msgs/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data",
    "geometry_msgs/TwistStamped": "std_msgs/Header header\ngeometry_msgs/Twist twist",
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist"
    ),
    "geometry_msgs/PoseWithCovariance": "geometry_msgs/Pose pose\nfloat64[36] covariance",
    "geometry_msgs/TwistWithCovariance": "geometry_msgs/Twist twist\nfloat64[36] covariance",
    "geometry_msgs/Pose": "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w",
    "sensor_msgs/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data"
    ),
    "rcl_interfaces/ParameterValue": (
        "uint8 type\nbool bool_value\nint64 integer_value\nfloat64 double_value\n"
        "string string_value\nbyte[] byte_array_value\nbool[] bool_array_value\n"
        "int64[] integer_array_value\nfloat64[] double_array_value\n"
        "string[] string_array_value"
    ),
}
_USES: dict[str, tuple[str, ...]] = {
    "geometry_msgs/Twist": ("geometry_msgs/Vector3",),
    "rosbridge_msgs/ConnectedClients": ("rosbridge_msgs/ConnectedClient",),
    "rosgraph_msgs/Log": ("std_msgs/Header",),
    "rcl_interfaces/Log": ("builtin_interfaces/Time",),
    "rcl_interfaces/ParameterEvent": (
        "builtin_interfaces/Time",
        "rcl_interfaces/Parameter",
        "rcl_interfaces/ParameterValue",
    ),
    "sensor_msgs/CompressedImage": ("std_msgs/Header",),
    "sensor_msgs/Image": ("std_msgs/Header",),
    "geometry_msgs/TwistStamped": ("std_msgs/Header", "geometry_msgs/Twist"),
    "nav_msgs/Odometry": (
        "std_msgs/Header",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/TwistWithCovariance",
    ),
    "geometry_msgs/PoseWithCovariance": ("geometry_msgs/Pose",),
    "geometry_msgs/TwistWithCovariance": ("geometry_msgs/Twist",),
    "geometry_msgs/Pose": ("geometry_msgs/Point", "geometry_msgs/Quaternion"),
}
# ROS 2's std_msgs/Header has no seq, and its stamp is a message of its own.
_ROS2_DEFINITIONS: dict[str, str] = {
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
}
_ROS2_USES: dict[str, tuple[str, ...]] = {"std_msgs/Header": ("builtin_interfaces/Time",)}


def _short(type_name: str) -> str:
    """``pkg/msg/Name`` -> ``pkg/Name``; the Jazzy package rename folded back for lookups."""
    parts = type_name.split("/")
    package, name = parts[0], parts[-1]
    return f"{'turtlesim' if package == 'turtlesim_msgs' else package}/{name}"


def full_text(type_name: str) -> str:
    """The ``typedefs_full_text`` entry for a message type of any flavour (a ROS 2 one is
    spelled ``pkg/msg/Name``): its definition, then every type it uses, depth first."""
    short = _short(type_name)
    ros2 = "/msg/" in type_name
    definitions = {**_DEFINITIONS, **_ROS2_DEFINITIONS} if ros2 else _DEFINITIONS
    uses = {**_USES, **_ROS2_USES} if ros2 else _USES
    text = definitions[short]
    seen = {short}
    pending = list(reversed(uses.get(short, ())))
    while pending:
        used = pending.pop()
        if used in seen:
            continue
        seen.add(used)
        text += f"\n{_SEPARATOR}\nMSG: {used}\n{definitions[used]}"
        pending.extend(reversed(uses.get(used, ())))
    return text


_Model = TypeVar("_Model", bound=BaseModel)


class RosapiError(Exception):
    """A rosapi call that the real rosapi would fail; becomes ``result: false``."""


class _Request(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class _Empty(_Request):
    pass


class _TopicRequest(_Request):
    topic: StrictStr = ""


class _ServiceRequest(_Request):
    service: StrictStr = ""


class _NodeRequest(_Request):
    node: StrictStr = ""


class _GetParamRequest(_Request):
    # ROS 1 rosapi calls the fallback ``default``, ROS 2 ``default_value``; both are JSON text.
    name: StrictStr = ""
    default: StrictStr = ""
    default_value: StrictStr = ""


class _SetParamRequest(_Request):
    name: StrictStr = ""
    value: StrictStr = ""


class RosGraph:
    """The graph of a robot of one ROS flavour, and rosapi's answers about it."""

    def __init__(
        self,
        sim: TurtleSim,
        flavour: RosFlavour,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        self.sim = sim
        self.flavour: RosFlavour = flavour
        self.types: RosTypes = TYPES[flavour]
        self._wall_clock = wall_clock
        self._ros1 = flavour == "1"
        self.params: dict[str, Any] = {self._param(n): v for n, v in BACKGROUND.items()}
        if self._ros1:
            self.params |= {"/rosdistro": "noetic\n", "/rosversion": "1.16.0\n"}
        else:
            self.params[self._param("use_sim_time")] = False
        if flavour == "jazzy":
            # The turtlesim_msgs-era node moves sideways only with this parameter set.
            self.params[self._param("holonomic")] = False
        self.sim.holonomic = flavour != "jazzy"
        # The calls about topics are answered from the topics listed for the caller.
        self._topic_handlers: dict[str, Callable[[Json, dict[str, str]], Json]] = {
            "topics": self._topics,
            "topics_and_raw_types": self._topics_and_raw_types,
            "topic_type": self._topic_type,
        }
        self._handlers: dict[str, Callable[[Json], Json]] = {
            "services": self._services,
            "service_type": self._service_type,
            "nodes": self._nodes,
            "node_details": self._node_details,
            "get_param": self._get_param,
            "set_param": self._set_param,
            "get_param_names": self._get_param_names,
            "get_time": self._get_time,
        }

    # -- the graph ---------------------------------------------------------------------------

    def topics(self) -> dict[str, str]:
        """Every topic and its type, sorted by name."""
        t = self.types
        kinds = {"cmd_vel": t.twist, "color_sensor": t.color, "pose": t.pose}
        found = {"/rosout": t.log}
        if self._ros1:
            found |= {
                "/rosout_agg": t.log,
                "/client_count": t.int32,
                "/connected_clients": t.connected_clients,
            }
        else:
            found["/parameter_events"] = t.parameter_event
        for turtle in self.sim.names():
            for leaf in TURTLE_TOPICS:
                found[f"/{turtle}/{leaf}"] = kinds[leaf]
        return dict(sorted(found.items()))

    def services(self) -> dict[str, str]:
        """Every service and its type, sorted by name."""
        t = self.types
        found = {
            "/clear": t.empty,
            "/kill": t.kill,
            "/reset": t.empty,
            "/spawn": t.spawn,
        }
        per_turtle = {
            "set_pen": t.set_pen,
            "teleport_absolute": t.teleport_absolute,
            "teleport_relative": t.teleport_relative,
        }
        for turtle in self.sim.names():
            for leaf, kind in per_turtle.items():
                found[f"/{turtle}/{leaf}"] = kind
        for leaf, name in ROSAPI_SERVICES.items():
            found[f"/rosapi/{leaf}"] = t.rosapi(name)
        return dict(sorted(found.items()))

    def nodes(self) -> list[str]:
        """The running nodes."""
        names = ["/rosapi", "/rosbridge_websocket", TURTLESIM_NODE]
        return sorted([*names, "/rosout"] if self._ros1 else names)

    def node_details(self, node: str) -> Json:
        """What ``node`` publishes, subscribes to and serves; empty lists for an unknown node."""
        topics = self.topics()
        services = self.services()
        turtles = [f"/{name}/" for name in self.sim.names()]
        extra = [] if self._ros1 else ["/parameter_events"]
        publishing: list[str] = []
        subscribing: list[str] = []
        serving: list[str] = []
        if node == TURTLESIM_NODE:
            publishing = ["/rosout", *extra]
            publishing += [t for t in topics if t.startswith(tuple(turtles)) and "cmd_vel" not in t]
            subscribing = [*extra, *(t for t in topics if t.endswith("/cmd_vel"))]
            serving = [s for s in services if not s.startswith("/rosapi/")]
        elif node == "/rosapi":
            publishing = ["/rosout"]
            serving = [s for s in services if s.startswith("/rosapi/")]
        elif node == "/rosbridge_websocket":
            publishing = ["/rosout"]
            if self._ros1:
                publishing += ["/client_count", "/connected_clients"]
        elif node == "/rosout" and self._ros1:
            publishing, subscribing = ["/rosout_agg"], ["/rosout"]
        return {
            "subscribing": sorted(subscribing),
            "publishing": sorted(publishing),
            "services": sorted(serving),
        }

    # -- rosapi calls ------------------------------------------------------------------------

    def call(self, service: str, args: Json, hosted: Mapping[str, str] | None = None) -> Json:
        """Answer rosapi's ``service`` (``topics``, ``get_param``, ...) called with ``args``;
        ``hosted`` are the topics the rosbridge carries for the caller's room and their types
        (:mod:`app.turtlesim.hosted`), listed beside the graph's: the clients' (through
        ``/rosbridge_websocket``), not a node's here."""
        about_topics = self._topic_handlers.get(service)
        if about_topics is not None:
            listed = dict(sorted({**self.topics(), **(hosted or {})}.items()))
            return about_topics(args, listed)
        try:
            handler = self._handlers[service]
        except KeyError:
            raise RosapiError(f"rosapi has no service {service!r} here") from None
        return handler(args)

    def _topics(self, args: Json, listed: dict[str, str]) -> Json:
        _parse(_Empty, args)
        return {"topics": list(listed), "types": list(listed.values())}

    def _topics_and_raw_types(self, args: Json, listed: dict[str, str]) -> Json:
        reply = self._topics(args, listed)
        reply["typedefs_full_text"] = [full_text(kind) for kind in reply["types"]]
        return reply

    def _topic_type(self, args: Json, listed: dict[str, str]) -> Json:
        name = _absolute(_parse(_TopicRequest, args).topic)
        return {"type": listed.get(name, "")}  # rosapi's answer for an unknown topic

    def _services(self, args: Json) -> Json:
        _parse(_Empty, args)
        return {"services": list(self.services())}

    def _service_type(self, args: Json) -> Json:
        name = _absolute(_parse(_ServiceRequest, args).service)
        return {"type": self.services().get(name, "")}

    def _nodes(self, args: Json) -> Json:
        _parse(_Empty, args)
        return {"nodes": self.nodes()}

    def _node_details(self, args: Json) -> Json:
        return self.node_details(_absolute(_parse(_NodeRequest, args).node))

    def _get_param(self, args: Json) -> Json:
        request = _parse(_GetParamRequest, args)
        name = self._canonical_param(request.name)
        if name in self.params:
            value = json.dumps(self.params[name])
            return {"value": value} if self._ros1 else _ok({"value": value})
        default_text = request.default or request.default_value
        default = _loads_or_text(default_text) if default_text else ""
        if self._ros1:
            return {"value": json.dumps(default)}
        return {
            "value": json.dumps(default),
            "successful": False,
            "reason": f"parameter {request.name!r} is not set",
        }

    def _set_param(self, args: Json) -> Json:
        request = _parse(_SetParamRequest, args)
        try:
            value = json.loads(request.value)
        except ValueError:
            raise RosapiError(
                "the value argument to set_param must be a JSON-formatted string"
            ) from None
        name = self._canonical_param(request.name)
        if self._ros1:
            # The ROS 1 parameter server takes any value under any name.
            self.params[name] = value
            return {}
        problem = self._ros2_param_problem(name, value)
        if problem:
            return {"successful": False, "reason": problem}
        self.params[name] = value
        if name == self._param("holonomic"):
            self.sim.holonomic = bool(value)
        return _ok({})

    def _get_param_names(self, args: Json) -> Json:
        _parse(_Empty, args)
        return {"names": sorted(self.params)}

    def _get_time(self, args: Json) -> Json:
        _parse(_Empty, args)
        fraction, whole = math.modf(self._wall_clock())
        secs, nsecs = int(whole), int(fraction * 1e9)
        if self._ros1:
            return {"time": {"secs": secs, "nsecs": nsecs}}
        return {"time": {"sec": secs, "nanosec": nsecs}}

    # -- parameters --------------------------------------------------------------------------

    def _param(self, name: str) -> str:
        """A turtlesim parameter's full name: ``/turtlesim/x`` (ROS 1), ``/turtlesim:x`` (2)."""
        return f"{TURTLESIM_NODE}{'/' if self._ros1 else ':'}{name}"

    def _canonical_param(self, name: str) -> str:
        if self._ros1:
            return _absolute(name)
        node, _, param = name.rpartition(":")
        return f"{_absolute(node)}:{param}" if node else name

    def _ros2_param_problem(self, name: str, value: object) -> str:
        """Why a ROS 2 node would refuse ``value`` for ``name``; empty when it takes it."""
        if name not in self.params:
            return f"parameter {name!r} is not declared"
        if name.endswith(tuple(BACKGROUND)):
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 255:
                return f"{name} takes an integer in 0..255, not {value!r}"
        elif not isinstance(value, bool):
            return f"{name} takes true or false, not {value!r}"
        return ""


def _ok(reply: Json) -> Json:
    return {**reply, "successful": True, "reason": ""}


def _absolute(name: str) -> str:
    return name if name.startswith("/") else f"/{name}"


def _loads_or_text(text: str) -> object:
    try:
        return json.loads(text)
    except ValueError:
        return text


def _parse(model: type[_Model], args: Json) -> _Model:
    try:
        return model.model_validate(args)
    except ValidationError as exc:
        raise RosapiError(f"args: {describe(exc)}") from None
