"""What rosbridge_suite's ``rosapi`` node answers about a simulated robot's graph, without I/O.

:class:`RosGraph` describes the ROS graph a real robot of one flavour shows with the robot's own
node (a :class:`GraphNode`: turtlesim's in :mod:`app.turtlesim.rosapi`, the differential-drive
robot's in :mod:`app.diffdrive.rosbridge`), ``rosbridge_websocket`` and ``rosapi`` running: its
topics (``/rosout`` included), services, nodes and parameters. It answers the rosapi calls that
Lichtblick/Foxglove, roslib.js and roslibpy make, in the request and response shapes of that
flavour's rosapi (``rosapi/*`` in ROS 1, ``rosapi_msgs/srv/*`` in ROS 2): ``GetTime`` is
``{secs, nsecs}`` in ROS 1 and ``{sec, nanosec}`` in ROS 2, ``GetParam`` and ``SetParam`` add
``successful``/``reason`` in ROS 2, parameter names are ``/node/param`` in ROS 1 and
``/node:param`` in ROS 2.

Listed but not simulated: ``/rosout``, ``/parameter_events`` and rosbridge's client topics exist
on the real graph and are reported, but nothing is published on them; the nodes' logger and
parameter services are left out of the lists.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from typing import Any, Protocol, TypeVar

from pydantic import BaseModel, ConfigDict, StrictStr, ValidationError

from app.protocol.errors import describe
from app.protocol.ros import TYPES, RosFlavour, RosTypes

Json = dict[str, Any]

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
# each type it uses (and they use, first met first) after a separator line and "MSG: <type>".
# ROS 1's, and ROS 2's where they differ (a Header's stamp is a builtin_interfaces/Time there).
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
    "rcl_interfaces/ParameterValue": (
        "uint8 type\nbool bool_value\nint64 integer_value\nfloat64 double_value\n"
        "string string_value\nbyte[] byte_array_value\nbool[] bool_array_value\n"
        "int64[] integer_array_value\nfloat64[] double_array_value\n"
        "string[] string_array_value"
    ),
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist"
    ),
    "geometry_msgs/PoseWithCovariance": "geometry_msgs/Pose pose\nfloat64[36] covariance",
    "geometry_msgs/Pose": "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w",
    "geometry_msgs/TwistWithCovariance": "geometry_msgs/Twist twist\nfloat64[36] covariance",
    "sensor_msgs/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data",
    "sensor_msgs/Image": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\n"
        "uint8 is_bigendian\nuint32 step\nuint8[] data"
    ),
    "geometry_msgs/TwistStamped": "std_msgs/Header header\ngeometry_msgs/Twist twist",
}
_ROS2_DEFINITIONS: dict[str, str] = {
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id",
}
# The types each type's fields use, in field order.
_USES: dict[str, tuple[str, ...]] = {
    "geometry_msgs/Twist": ("geometry_msgs/Vector3",),
    "rosbridge_msgs/ConnectedClients": ("rosbridge_msgs/ConnectedClient",),
    "rosgraph_msgs/Log": ("std_msgs/Header",),
    "rcl_interfaces/Log": ("builtin_interfaces/Time",),
    "rcl_interfaces/ParameterEvent": ("builtin_interfaces/Time", "rcl_interfaces/Parameter"),
    "rcl_interfaces/Parameter": ("rcl_interfaces/ParameterValue",),
    "nav_msgs/Odometry": (
        "std_msgs/Header",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/TwistWithCovariance",
    ),
    "geometry_msgs/PoseWithCovariance": ("geometry_msgs/Pose",),
    "geometry_msgs/Pose": ("geometry_msgs/Point", "geometry_msgs/Quaternion"),
    "geometry_msgs/TwistWithCovariance": ("geometry_msgs/Twist",),
    "sensor_msgs/CompressedImage": ("std_msgs/Header",),
    "sensor_msgs/Image": ("std_msgs/Header",),
    "geometry_msgs/TwistStamped": ("std_msgs/Header", "geometry_msgs/Twist"),
}
_ROS2_USES: dict[str, tuple[str, ...]] = {
    "std_msgs/Header": ("builtin_interfaces/Time",),
}


def _short(type_name: str) -> str:
    """``pkg/msg/Name`` -> ``pkg/Name``; the Jazzy package rename folded back for lookups."""
    parts = type_name.split("/")
    package, name = parts[0], parts[-1]
    return f"{'turtlesim' if package == 'turtlesim_msgs' else package}/{name}"


def full_text(type_name: str) -> str:
    """The ``typedefs_full_text`` entry for a message type of any flavour (ROS 2's spelling,
    ``pkg/msg/Name``, gives ROS 2's definitions)."""
    ros2 = type_name.count("/") == 2
    definitions = {**_DEFINITIONS, **_ROS2_DEFINITIONS} if ros2 else _DEFINITIONS
    uses = {**_USES, **_ROS2_USES} if ros2 else _USES
    short = _short(type_name)
    met: list[str] = []

    def walk(kind: str) -> None:
        for used in uses.get(kind, ()):
            if used not in met:
                met.append(used)
                walk(used)

    walk(short)
    # A hosted topic's type (a robot's, app/rosbridge/hosted.py) may not be described here.
    return definitions.get(short, "") + "".join(
        f"\n{_SEPARATOR}\nMSG: {used}\n{definitions[used]}" for used in met
    )


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


class GraphNode(Protocol):
    """The simulated robot's own node: what it publishes, listens to, serves and is set by.

    Topic and service maps are full names to types as the graph's flavour spells them;
    parameters are by their short names (the graph puts the node's name in front).
    """

    name: str

    def publishes(self, graph: RosGraph) -> dict[str, str]:
        """Topics the node publishes."""
        ...

    def subscribes(self, graph: RosGraph) -> dict[str, str]:
        """Topics the node listens to."""
        ...

    def serves(self, graph: RosGraph) -> dict[str, str]:
        """The node's own services."""
        ...

    def parameters(self, graph: RosGraph) -> dict[str, Any]:
        """The node's parameters and their values at start."""
        ...

    def parameter_problem(self, name: str, value: object) -> str | None:
        """The rule ``value`` breaks for the node's parameter ``name`` (ROS 2), e.g. "takes an
        integer in 0..255"; "" when it takes it, None to leave it to the rule every other
        parameter here follows (true or false)."""
        ...

    def parameter_set(self, name: str, value: object) -> None:
        """The node's parameter ``name`` was set to ``value`` (ROS 2): what follows from it."""
        ...


class RosGraph:
    """The graph of a robot of one ROS flavour, and rosapi's answers about it."""

    def __init__(
        self,
        node: GraphNode,
        flavour: RosFlavour,
        wall_clock: Callable[[], float] = time.time,
    ) -> None:
        self.node = node
        # The topics the rosbridge carries for its clients (app/rosbridge/hosted.py) and their
        # types: on the graph while they are hosted (its hub sets this).
        self.hosted: Callable[[], dict[str, str]] = dict
        self.flavour: RosFlavour = flavour
        self.types: RosTypes = TYPES[flavour]
        self._wall_clock = wall_clock
        self._ros1 = flavour == "1"
        own = node.parameters(self)
        if not self._ros1:
            own = {"use_sim_time": False, **own}
        self.params: dict[str, Any] = {self._param(n): v for n, v in own.items()}
        if self._ros1:
            self.params |= {"/rosdistro": "noetic\n", "/rosversion": "1.16.0\n"}
        self._handlers: dict[str, Callable[[Json], Json]] = {
            "topics": self._topics,
            "topics_and_raw_types": self._topics_and_raw_types,
            "topic_type": self._topic_type,
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
        found = {"/rosout": t.log}
        if self._ros1:
            found |= {
                "/rosout_agg": t.log,
                "/client_count": t.int32,
                "/connected_clients": t.connected_clients,
            }
        else:
            found["/parameter_events"] = t.parameter_event
        found |= self.node.publishes(self) | self.node.subscribes(self)
        return dict(sorted((self.hosted() | found).items()))

    def services(self) -> dict[str, str]:
        """Every service and its type, sorted by name."""
        found = dict(self.node.serves(self))
        for leaf, name in ROSAPI_SERVICES.items():
            found[f"/rosapi/{leaf}"] = self.types.rosapi(name)
        return dict(sorted(found.items()))

    def nodes(self) -> list[str]:
        """The running nodes."""
        names = ["/rosapi", "/rosbridge_websocket", self.node.name]
        return sorted([*names, "/rosout"] if self._ros1 else names)

    def node_details(self, node: str) -> Json:
        """What ``node`` publishes, subscribes to and serves; empty lists for an unknown node."""
        extra = [] if self._ros1 else ["/parameter_events"]
        publishing: list[str] = []
        subscribing: list[str] = []
        serving: list[str] = []
        if node == self.node.name:
            publishing = ["/rosout", *extra, *self.node.publishes(self)]
            subscribing = [*extra, *self.node.subscribes(self)]
            serving = list(self.node.serves(self))
        elif node == "/rosapi":
            publishing = ["/rosout"]
            serving = [s for s in self.services() if s.startswith("/rosapi/")]
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

    def call(self, service: str, args: Json) -> Json:
        """Answer rosapi's ``service`` (``topics``, ``get_param``, ...) called with ``args``."""
        try:
            handler = self._handlers[service]
        except KeyError:
            raise RosapiError(f"rosapi has no service {service!r} here") from None
        return handler(args)

    def _topics(self, args: Json) -> Json:
        _parse(_Empty, args)
        topics = self.topics()
        return {"topics": list(topics), "types": list(topics.values())}

    def _topics_and_raw_types(self, args: Json) -> Json:
        reply = self._topics(args)
        reply["typedefs_full_text"] = [full_text(kind) for kind in reply["types"]]
        return reply

    def _topic_type(self, args: Json) -> Json:
        name = _absolute(_parse(_TopicRequest, args).topic)
        return {"type": self.topics().get(name, "")}  # rosapi's answer for an unknown topic

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
        node, _, short = name.rpartition(":")
        if node == self.node.name:
            self.node.parameter_set(short, value)
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
        """A node parameter's full name: ``/node/x`` (ROS 1), ``/node:x`` (ROS 2)."""
        return f"{self.node.name}{'/' if self._ros1 else ':'}{name}"

    def _canonical_param(self, name: str) -> str:
        if self._ros1:
            return _absolute(name)
        node, _, param = name.rpartition(":")
        return f"{_absolute(node)}:{param}" if node else name

    def _ros2_param_problem(self, name: str, value: object) -> str:
        """Why a ROS 2 node would refuse ``value`` for ``name``; empty when it takes it."""
        if name not in self.params:
            return f"parameter {name!r} is not declared"
        node, _, short = name.rpartition(":")
        problem = self.node.parameter_problem(short, value) if node == self.node.name else None
        if problem is None:
            problem = "" if isinstance(value, bool) else "takes true or false"
        return f"{name} {problem}, not {value!r}" if problem else ""


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
