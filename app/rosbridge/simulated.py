"""What the server asks of a simulated robot, whichever it is.

The server (:mod:`app.server.rosbridge`) serves a robot's :class:`~app.rosbridge.protocol.Hub` on
``/rosbridge``, steps it every tick, films its camera while anyone subscribes and answers its
state for the client's map, all through these protocols: it names no simulator. A
:class:`Simulation` is one kind of robot (turtlesim's turtle, the diffdrive robot in its arena)
and makes its robots; :mod:`app.simulators` names each kind, and ``autopilot serve --robot NAME``
picks one.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from app.protocol.page import ArenaMap
from app.protocol.ros import RosFlavour
from app.rosbridge.protocol import Hub


class Camera(Protocol):
    """A simulated robot's camera, filmed by the server at :attr:`fps` while anyone subscribes.

    Rendering is slow beside a tick, so the server takes a :meth:`shot` on its loop (the scene
    as of now, which no later tick changes) and renders it in its camera thread.
    """

    @property
    def fps(self) -> float:
        """Frames per second the camera is filmed at."""
        ...

    def wanted(self) -> bool:
        """Whether anyone subscribes to the camera: nothing is rendered for no one."""
        ...

    def prepare(self) -> None:
        """Load what rendering needs, once, before the first frame (in the camera thread)."""
        ...

    def shot(self) -> Callable[[], bytes]:
        """The frame as of now, as a call that renders it to JPEG (in the camera thread)."""
        ...

    def publish(self, jpeg: bytes, stamp_s: float) -> None:
        """A rendered frame, taken at ``stamp_s`` (Unix seconds), for the camera's subscribers."""
        ...


class SimulatedRobot(Protocol):
    """One simulated robot: its rosbridge hub, the step the server's tick makes, its camera,
    and its state for the client's map."""

    @property
    def hub(self) -> Hub[Any]:
        """The robot as rosbridge shows it: its topics, services and graph."""
        ...

    @property
    def camera(self) -> Camera | None:
        """Its camera; None for a robot that carries none."""
        ...

    def step(self, now: float) -> None:
        """One fixed tick of the robot, then of its hub (``now``: the monotonic clock)."""
        ...

    def state(self) -> dict[str, Any]:
        """What the map shows of it now, JSON-ready (``GET`` :attr:`Simulation.state_path`)."""
        ...


class Simulation(Protocol):
    """One kind of simulated robot: how many the server runs, and how it makes and shows them."""

    @property
    def per_room(self) -> bool:
        """True: a robot for each signaling room, bound to it; False: one for the whole
        server, which every room reaches."""
        ...

    @property
    def tick_s(self) -> float:
        """The fixed time its robots advance by at each step: the server steps them that often,
        so pacing the loop any other way would only change their speed."""
        ...

    @property
    def state_path(self) -> str:
        """The ``GET`` route that answers a robot's :meth:`SimulatedRobot.state`."""
        ...

    def robot(self, ros: RosFlavour) -> SimulatedRobot:
        """A new robot at its start, speaking ``ros``'s type names."""
        ...

    def arena_map(self) -> ArenaMap | None:
        """The arena the client's map draws; None: turtlesim's terrain."""
        ...
