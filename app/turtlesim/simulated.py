"""turtlesim as the server simulates it (:mod:`app.rosbridge.simulated`): one simulator for the
whole server, which every room reaches, with no camera; its state for the map is the turtles'
poses and pens and the pen strokes (``GET /turtlesim/state``)."""

from __future__ import annotations

from dataclasses import asdict
from typing import Any, Final

from app.protocol.page import ArenaMap
from app.protocol.ros import RosFlavour
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import TurtleSim

STATE_PATH: Final = "/turtlesim/state"


class TurtleRobot:
    """turtlesim's simulator and its hub."""

    camera: Final = None

    def __init__(self, ros: RosFlavour) -> None:
        self.sim = TurtleSim()
        self.hub = RosbridgeHub(self.sim, ros)

    def step(self, now: float) -> None:
        """One tick of the simulator, then of its hub."""
        self.sim.step()
        self.hub.tick(now)

    def state(self) -> dict[str, Any]:
        """The turtles' poses and pens and the pen strokes, as JSON-ready data."""
        sim = self.sim
        turtles = [
            {"name": name, **asdict(sim.pose(name)), "pen": asdict(sim.pen(name))}
            for name in sim.names()
        ]
        strokes = [
            {"turtle": s.turtle, "pen": asdict(s.pen), "points": s.points} for s in sim.strokes()
        ]
        return {
            "world_size": TurtleSim.WORLD_SIZE,
            "tick": sim.ticks,
            "turtles": turtles,
            "strokes": strokes,
        }


class TurtleSimulation:
    """turtlesim: one turtle simulator for the whole server."""

    per_room: Final = False
    tick_s: Final = TurtleSim.TICK_S
    state_path: Final = STATE_PATH

    def robot(self, ros: RosFlavour) -> TurtleRobot:
        """A fresh simulator with turtle1 at the centre."""
        return TurtleRobot(ros)

    def arena_map(self) -> ArenaMap | None:
        """None: the client draws turtlesim's terrain."""
        return None
