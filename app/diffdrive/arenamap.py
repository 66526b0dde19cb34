"""The arena as the client's map shows it: its layout in the page config, the billboards' places
now in ``GET /arena/state`` -- both made here from the arena the simulator runs, so the map draws
what the camera sees."""

from __future__ import annotations

from typing import Final

from app.diffdrive.arena import Arena
from app.diffdrive.robot import DiffDrive
from app.diffdrive.sim import Scene
from app.protocol.page import ArenaMap, ArenaState, BillboardMark, PlacedMark

STATE_PATH: Final = "/arena/state"
# How often the client reads the billboards' places: the walker moves 16 cm between two reads
# at its jog, less than its own width on the map.
STATE_PERIOD_MS: Final = 100


def arena_map(arena: Arena, hfov: float) -> ArenaMap:
    """The layout of ``arena`` for the page config; ``hfov`` is the robot camera's (radians)."""
    marks = []
    for billboard in arena.billboards:
        start = billboard.placed(0.0, (arena.start.x, arena.start.y))
        walk = billboard.walk
        path = () if walk is None else (walk.start, *(leg.to for leg in walk.legs))
        marks.append(
            BillboardMark(
                name=billboard.name,
                kind=billboard.look.kind,
                width=billboard.look.picture.width,
                x=start.x,
                y=start.y,
                yaw=start.yaw,
                walk=path,
            )
        )
    return ArenaMap(
        width=arena.width,
        depth=arena.depth,
        robot_radius=DiffDrive.RADIUS_M,
        hfov=hfov,
        billboards=tuple(marks),
        state_path=STATE_PATH,
        state_period_ms=STATE_PERIOD_MS,
    )


def arena_state(scene: Scene) -> ArenaState:
    """Where the billboards of ``scene`` stand, for ``GET /arena/state``."""
    return ArenaState(
        t=scene.t,
        billboards=tuple(
            PlacedMark(p.billboard.name, p.pose.x, p.pose.y, p.pose.yaw) for p in scene.billboards
        ),
    )
