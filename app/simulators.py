"""The robots the server can simulate, by name (``autopilot serve --robot NAME``).

The one place that names each simulator: the server asks :func:`simulation` for the one it was
started with and then knows it only as an :class:`~app.rosbridge.simulated.Simulation`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final, Literal, get_args

from app.diffdrive.simulated import DiffDriveSimulation
from app.rosbridge.simulated import Simulation
from app.turtlesim.simulated import TurtleSimulation

# turtlesim's turtle (one for the whole server), or a differential-drive robot with an onboard
# camera in a walled arena (one per room).
SimulatorName = Literal["turtlesim", "diffdrive"]
SIMULATOR_NAMES: Final[tuple[SimulatorName, ...]] = get_args(SimulatorName)
SIMULATORS: Final[dict[SimulatorName, Callable[[], Simulation]]] = {
    "turtlesim": TurtleSimulation,
    "diffdrive": DiffDriveSimulation,
}
# What each is, for ``--robot``'s help.
SIMULATOR_HELP: Final[dict[SimulatorName, str]] = {
    "turtlesim": "turtlesim's turtle, one for the whole server",
    "diffdrive": "a differential-drive robot with a camera in a walled arena, one per room",
}
# The robot a server simulates when it is not told which.
DEFAULT_SIMULATOR: Final[SimulatorName] = "turtlesim"


def simulation(name: SimulatorName) -> Simulation:
    """A fresh simulation of the robot called ``name``: its robots share nothing with another
    server's."""
    return SIMULATORS[name]()
