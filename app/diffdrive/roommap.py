"""The room as the client's map shows it: its layout in the page config, the billboards' places
now in ``GET /room/state`` -- both made here from the room the simulator runs, so the map draws
what the camera sees."""

from __future__ import annotations

from typing import Final

from app.diffdrive.robot import DiffDrive
from app.diffdrive.room import Room
from app.diffdrive.sim import Scene
from app.protocol.page import BillboardMark, PlacedMark, RoomMap, RoomState

STATE_PATH: Final = "/room/state"
# How often the client reads the billboards' places: the walker moves 16 cm between two reads
# at its jog, less than its own width on the map.
STATE_PERIOD_MS: Final = 100


def room_map(room: Room, hfov: float) -> RoomMap:
    """The layout of ``room`` for the page config; ``hfov`` is the robot camera's (radians)."""
    marks = []
    for billboard in room.billboards:
        start = billboard.placed(0.0, (room.start.x, room.start.y))
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
    return RoomMap(
        width=room.width,
        depth=room.depth,
        robot_radius=DiffDrive.RADIUS_M,
        hfov=hfov,
        billboards=tuple(marks),
        state_path=STATE_PATH,
        state_period_ms=STATE_PERIOD_MS,
    )


def room_state(scene: Scene) -> RoomState:
    """Where the billboards of ``scene`` stand, for ``GET /room/state``."""
    return RoomState(
        t=scene.t,
        billboards=tuple(
            PlacedMark(p.billboard.name, p.pose.x, p.pose.y, p.pose.yaw) for p in scene.billboards
        ),
    )
