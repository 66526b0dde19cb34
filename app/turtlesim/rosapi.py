"""turtlesim's node on the ROS graph, as rosapi describes it (:mod:`app.rosbridge.rosapi`).

A real ``turtlesim_node`` publishes each turtle's ``pose`` and ``color_sensor``, listens to its
``cmd_vel``, serves ``clear``, ``kill``, ``reset``, ``spawn`` and each turtle's pen and teleports,
and has the background colour as parameters (69, 86, 255); the Jazzy one has ``holonomic`` too.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from app.turtlesim.sim import TurtleSim

if TYPE_CHECKING:
    from app.rosbridge.rosapi import RosGraph

TURTLESIM_NODE = "/turtlesim"
# turtlesim's own services: global, then per turtle (/<turtle>/<name>).
GLOBAL_SERVICES = ("clear", "kill", "reset", "spawn")
TURTLE_SERVICES = ("set_pen", "teleport_absolute", "teleport_relative")
# The topics every turtle has, by leaf name.
TURTLE_TOPICS = ("cmd_vel", "color_sensor", "pose")
# turtlesim's default background (turtle_frame's DEFAULT_BG_R/G/B).
BACKGROUND = {"background_r": 69, "background_g": 86, "background_b": 255}


class TurtlesimNode:
    """``/turtlesim`` on the graph: its topics and services follow the living turtles."""

    name = TURTLESIM_NODE

    def __init__(self, sim: TurtleSim) -> None:
        self.sim = sim

    def publishes(self, graph: RosGraph) -> dict[str, str]:
        """Each turtle's pose and colour sensor."""
        t = graph.types
        kinds = {"color_sensor": t.color, "pose": t.pose}
        return {
            f"/{turtle}/{leaf}": kind for turtle in self.sim.names() for leaf, kind in kinds.items()
        }

    def subscribes(self, graph: RosGraph) -> dict[str, str]:
        """Each turtle's cmd_vel."""
        return {f"/{turtle}/cmd_vel": graph.types.twist for turtle in self.sim.names()}

    def serves(self, graph: RosGraph) -> dict[str, str]:
        """turtlesim's own services and each turtle's."""
        t = graph.types
        found = {"/clear": t.empty, "/kill": t.kill, "/reset": t.empty, "/spawn": t.spawn}
        per_turtle = {
            "set_pen": t.set_pen,
            "teleport_absolute": t.teleport_absolute,
            "teleport_relative": t.teleport_relative,
        }
        for turtle in self.sim.names():
            for leaf, kind in per_turtle.items():
                found[f"/{turtle}/{leaf}"] = kind
        return found

    def parameters(self, graph: RosGraph) -> dict[str, Any]:
        """The background colour; the turtlesim_msgs-era node (Jazzy) moves sideways only with
        ``holonomic`` set, and starts without."""
        found: dict[str, Any] = dict(BACKGROUND)
        if graph.flavour == "jazzy":
            found["holonomic"] = False
        return found

    def parameter_problem(self, name: str, value: object) -> str | None:
        """A background colour is an integer in 0..255; the rest are booleans."""
        if name not in BACKGROUND:
            return None
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 255:
            return "takes an integer in 0..255"
        return ""

    def parameter_set(self, name: str, value: object) -> None:
        """``holonomic`` switches the sideways move of cmd_vel's ``linear.y`` on or off."""
        if name == "holonomic":
            self.sim.holonomic = bool(value)
