"""The simulated robots behind one interface (app/simulators.py, app/rosbridge/simulated.py):
the registry names each, every robot steps, serves its hub and answers its state the same way,
and the server names none of them."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from typing import get_args

import pytest

from app.diffdrive.arena import ARENA
from app.protocol.rooms import DEFAULT_ROOM
from app.resources import APP_DIR
from app.server.config import Settings
from app.server.rosbridge import Simulator
from app.server.websocket import SocketPolicy
from app.simulators import SIMULATOR_NAMES, SIMULATORS, SimulatorName, simulation

JPEG_START = b"\xff\xd8"


def test_the_registry_names_every_simulator_the_settings_accept() -> None:
    assert set(SIMULATORS) == set(SIMULATOR_NAMES) == set(get_args(SimulatorName))
    assert SIMULATOR_NAMES == ("turtlesim", "diffdrive")
    for name in SIMULATOR_NAMES:
        Settings(robot=name)  # the setting takes each name the registry has


@pytest.mark.parametrize("name", SIMULATOR_NAMES)
def test_every_robot_steps_its_hub_and_answers_its_state_as_json(name: SimulatorName) -> None:
    robot = simulation(name).robot("2")
    session = robot.hub.open_session()
    before = json.dumps(robot.state(), allow_nan=False)
    for tick in range(1, 4):
        robot.step(float(tick))
    assert robot.hub.ticks == 3
    assert json.dumps(robot.state(), allow_nan=False) != before  # the simulation's time moved on
    session.close()


def test_turtlesim_is_one_robot_for_every_room_with_no_camera_or_arena() -> None:
    turtlesim = simulation("turtlesim")
    assert not turtlesim.per_room
    assert turtlesim.state_path == "/turtlesim/state"
    assert turtlesim.arena_map() is None
    robot = turtlesim.robot("1")
    assert robot.camera is None
    assert [t["name"] for t in robot.state()["turtles"]] == ["turtle1"]


def test_the_diffdrive_robot_is_one_per_room_and_films_its_arena_only_when_watched() -> None:
    diffdrive = simulation("diffdrive")
    assert diffdrive.per_room
    assert diffdrive.state_path == "/arena/state"
    arena = diffdrive.arena_map()
    assert arena is not None and (arena.width, arena.depth) == (ARENA.width, ARENA.depth)
    robot = diffdrive.robot("2")
    camera = robot.camera
    assert camera is not None and camera.fps > 0
    assert not camera.wanted()
    session = robot.hub.open_session()
    session.receive(json.dumps({"op": "subscribe", "topic": "/camera/image/compressed"}))
    assert camera.wanted()
    camera.prepare()
    jpeg = camera.shot()()
    assert jpeg.startswith(JPEG_START)
    camera.publish(jpeg, 1_700_000_000.0)
    robot.step(1.0)
    [frame] = [m for m in session.take_publications() if m["topic"].startswith("/camera")]
    assert frame["msg"]["format"] == "jpeg"
    assert {b["name"] for b in robot.state()["billboards"]} == {b.name for b in ARENA.billboards}


def test_a_room_without_a_robot_yet_shows_one_at_its_start_and_makes_none() -> None:
    policy = SocketPolicy.from_settings(Settings())
    simulator = Simulator(policy, robot="diffdrive")
    state = simulator.state("nobody-here")
    assert state["t"] == 0.0
    assert simulator.rooms == {}
    shared = Simulator(policy, robot="turtlesim")
    # One turtle simulator, whichever room asks.
    assert shared.hub_for("a") is shared.hub_for("b") is shared.hub_for(DEFAULT_ROOM)


def test_the_server_names_no_simulator() -> None:
    """Neither imports one nor spells a simulator's name: the registry does (its default too)."""
    server = APP_DIR / "server"
    named: dict[str, list[str]] = {}
    for path in sorted(server.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module is not None:
                names = [node.module]
            elif isinstance(node, ast.Constant) and node.value in SIMULATOR_NAMES:
                names = [repr(node.value)]
            for name in names:
                if name.startswith(("app.turtlesim", "app.diffdrive")) or name.startswith("'"):
                    named.setdefault(str(path.relative_to(APP_DIR)), []).append(name)
    assert named == {}


def test_a_server_that_films_nothing_never_loads_the_renderer() -> None:
    probe = (
        "import sys\n"
        "from app.server.app import create_app\n"
        "from app.server.config import Settings\n"
        "create_app(Settings(robot='diffdrive'))\n"
        "print('app.diffdrive.camera' in sys.modules, 'cv2' in sys.modules)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=APP_DIR.parent,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["False", "False"]
