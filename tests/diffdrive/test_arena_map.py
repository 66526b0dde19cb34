"""The client's map of the simulated arena: the layout in the page config, the billboards'
places in ``GET /arena/state``; neither when the server simulates turtlesim."""

from __future__ import annotations

import math
from collections.abc import Callable

import httpx
import pytest

from app.diffdrive.arena import ARENA, FLAME_AT, WALK
from app.diffdrive.robot import CAMERA_HFOV, DiffDrive
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.server.test_pages import embedded_config


@pytest.fixture
def diffdrive(
    start_server: Callable[[Settings], RunningServer], settings: Settings
) -> RunningServer:
    return start_server(settings.model_copy(update={"robot": "diffdrive"}))


def test_the_client_config_carries_the_arena_when_the_server_simulates_one(
    diffdrive: RunningServer,
) -> None:
    config = embedded_config(httpx.get(diffdrive.url + "/client?room=r1").text)
    arena = config["arenaMap"]
    assert (arena["width"], arena["depth"]) == (ARENA.width, ARENA.depth)
    assert arena["robotRadius"] == DiffDrive.RADIUS_M
    assert arena["hfov"] == pytest.approx(CAMERA_HFOV)
    assert arena["statePath"] == "/arena/state"
    marks = {b["name"]: b for b in arena["billboards"]}
    assert set(marks) == {b.name for b in ARENA.billboards}
    walker = marks["walker"]
    assert walker["kind"] == "face"
    assert [tuple(p) for p in walker["walk"]] == [WALK.start, *(leg.to for leg in WALK.legs)]
    flame = marks["flame"]
    assert flame["kind"] == "flame" and flame["walk"] == []
    assert (flame["x"], flame["y"]) == FLAME_AT


def test_a_turtlesim_server_has_no_arena(server: RunningServer) -> None:
    config = embedded_config(httpx.get(server.url + "/client").text)
    assert config["arenaMap"] is None
    assert httpx.get(server.url + "/arena/state").status_code == 404


def test_the_arena_state_follows_the_walker(diffdrive: RunningServer) -> None:
    first = httpx.get(diffdrive.url + "/arena/state?room=r2").json()
    assert {b["name"] for b in first["billboards"]} == {b.name for b in ARENA.billboards}
    walker = next(b for b in first["billboards"] if b["name"] == "walker")
    assert (walker["x"], walker["y"]) == pytest.approx(WALK.at(first["t"]), abs=1e-9)
    # Facing the robot at its start: no connection has moved it.
    facing = math.atan2(ARENA.start.y - walker["y"], ARENA.start.x - walker["x"])
    assert walker["yaw"] == pytest.approx(facing)
