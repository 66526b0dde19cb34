"""The client's map of the simulated room: the layout in the page config, the billboards'
places in ``GET /room/state``; neither when the server simulates turtlesim."""

from __future__ import annotations

import math
from collections.abc import Callable

import httpx
import pytest

from app.diffdrive.robot import CAMERA_HFOV, DiffDrive
from app.diffdrive.room import FLAME_AT, ROOM, WALK
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.server.test_pages import embedded_config


@pytest.fixture
def diffdrive(
    start_server: Callable[[Settings], RunningServer], settings: Settings
) -> RunningServer:
    return start_server(settings.model_copy(update={"robot": "diffdrive"}))


def test_the_client_config_carries_the_room_when_the_server_simulates_one(
    diffdrive: RunningServer,
) -> None:
    config = embedded_config(httpx.get(diffdrive.url + "/client?room=r1").text)
    room = config["roomMap"]
    assert (room["width"], room["depth"]) == (ROOM.width, ROOM.depth)
    assert room["robotRadius"] == DiffDrive.RADIUS_M
    assert room["hfov"] == pytest.approx(CAMERA_HFOV)
    assert room["statePath"] == "/room/state"
    marks = {b["name"]: b for b in room["billboards"]}
    assert set(marks) == {b.name for b in ROOM.billboards}
    walker = marks["walker"]
    assert walker["kind"] == "face"
    assert [tuple(p) for p in walker["walk"]] == [WALK.start, *(leg.to for leg in WALK.legs)]
    flame = marks["flame"]
    assert flame["kind"] == "flame" and flame["walk"] == []
    assert (flame["x"], flame["y"]) == FLAME_AT


def test_a_turtlesim_server_has_no_room(server: RunningServer) -> None:
    config = embedded_config(httpx.get(server.url + "/client").text)
    assert config["roomMap"] is None
    assert httpx.get(server.url + "/room/state").status_code == 404


def test_the_room_state_follows_the_walker(diffdrive: RunningServer) -> None:
    first = httpx.get(diffdrive.url + "/room/state?room=r2").json()
    assert {b["name"] for b in first["billboards"]} == {b.name for b in ROOM.billboards}
    walker = next(b for b in first["billboards"] if b["name"] == "walker")
    assert (walker["x"], walker["y"]) == pytest.approx(WALK.at(first["t"]), abs=1e-9)
    # Facing the robot at its start: no connection has moved it.
    facing = math.atan2(ROOM.start.y - walker["y"], ROOM.start.x - walker["x"])
    assert walker["yaw"] == pytest.approx(facing)
