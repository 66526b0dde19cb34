"""One arena's simulation: the robot, and the arena's time that moves the walking billboard.

:class:`ArenaSim` steps both at the robot's fixed tick; :meth:`ArenaSim.scene` is what the
camera renders, taken at one instant, so a renderer working elsewhere (another thread) reads
nothing that the next tick changes.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from app.diffdrive.arena import ARENA, Arena, Billboard, Pose2D
from app.diffdrive.robot import DiffDrive, RobotState


@dataclass(frozen=True)
class Placed:
    """A billboard where it stands at one instant."""

    billboard: Billboard
    pose: Pose2D


@dataclass(frozen=True)
class Scene:
    """Everything the camera sees at one instant: the robot's state and the billboards."""

    t: float
    robot: RobotState
    billboards: tuple[Placed, ...]
    # Counts the arena's ticks: tells one scene from the next (a flame flickers with it).
    tick: int


class ArenaSim:
    """The robot in ``arena``; the arena's time is its ticks times the tick."""

    def __init__(self, arena: Arena = ARENA, clock: Callable[[], float] = time.monotonic) -> None:
        self.arena = arena
        start = arena.start
        self.robot = DiffDrive(arena.width, arena.depth, start.x, start.y, start.yaw, clock)
        self.ticks = 0

    @property
    def t(self) -> float:
        """Arena time (s) since the simulation began: the billboards' walks run on it."""
        return self.ticks * DiffDrive.TICK_S

    def step(self) -> None:
        """One tick of the robot and of the arena's time."""
        self.robot.step()
        self.ticks += 1

    def scene(self) -> Scene:
        """The robot and the billboards now."""
        robot = self.robot.state()
        t = self.t
        placed = tuple(Placed(b, b.placed(t, (robot.x, robot.y))) for b in self.arena.billboards)
        return Scene(t, robot, placed, self.ticks)
