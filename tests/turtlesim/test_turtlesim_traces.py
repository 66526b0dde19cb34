"""The simulator, driven through rosbridge, publishes what the real turtlesim does, tick for tick.

Each trace in ``traces/`` is a Twist and service sequence with the poses the real
``turtlesim_node`` publishes after every tick, derived by hand from the facts in
``docs/turtlesim-facts.md`` (see ``traces/derive.py``; never from our simulator). Here the same
sequence goes to the simulator as rosbridge JSON, and every ``/<turtle>/pose`` publication of
every tick is compared with the trace.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from app.protocol.ros import RosFlavour
from app.rosbridge.protocol import RosbridgeSession
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import TurtleSim

TRACES = Path(__file__).resolve().parent / "traces"
# Published pose fields are float32 (the traces are in double): half a float32 step near 11 m.
FLOAT32_SLACK = 1e-6
FIELDS = ("x", "y", "theta", "linear_velocity", "angular_velocity")


def cases() -> list[Any]:
    found = []
    for path in sorted(TRACES.glob("*.json")):
        trace = json.loads(path.read_text())
        for flavour in trace["flavours"]:
            found.append(pytest.param(trace, flavour, id=f"{path.stem}-ros{flavour}"))
    return found


def as_rosbridge(action: dict[str, Any], flavour: RosFlavour) -> list[dict[str, Any]]:
    """A trace action as the rosbridge messages a client sends for it."""
    op = action["op"]
    if op == "cmd_vel":
        twist = {
            "linear": {**action["linear"], "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": action["angular_z"]},
        }
        return [{"op": "publish", "topic": f"/{action['turtle']}/cmd_vel", "msg": twist}]
    args = {k: v for k, v in action.items() if k not in ("op", "turtle")}
    if op == "spawn":
        pose_type = "turtlesim_msgs/msg/Pose" if flavour == "jazzy" else None
        subscribe = {"op": "subscribe", "topic": f"/{action['name']}/pose"}
        if pose_type:
            subscribe["type"] = pose_type
        return [{"op": "call_service", "service": "/spawn", "args": args}, subscribe]
    return [{"op": "call_service", "service": f"/{action['turtle']}/{op}", "args": args}]


def send(session: RosbridgeSession, message: dict[str, Any]) -> None:
    replies = session.receive(json.dumps(message))
    failed = [r for r in replies if r.get("result") is False or r["op"] == "status"]
    assert not failed, failed


@pytest.mark.parametrize(("trace", "flavour"), cases())
def test_simulator_matches_the_real_turtlesim_trace(
    trace: dict[str, Any], flavour: RosFlavour
) -> None:
    clock = {"now": 0.0}
    sim = TurtleSim(clock=lambda: clock["now"])
    hub = RosbridgeHub(sim, flavour)
    session = hub.open_session()
    send(session, {"op": "set_level", "level": "warning"})
    send(session, {"op": "subscribe", "topic": "/turtle1/pose"})
    for tick, step in enumerate(trace["steps"], start=1):
        for action in step["before"]:
            for message in as_rosbridge(action, flavour):
                send(session, message)
        clock["now"] = tick * TurtleSim.TICK_S
        sim.step()
        hub.tick(clock["now"])
        published = {
            p["topic"].split("/")[1]: [p["msg"][f] for f in FIELDS]
            for p in session.take_publications()
        }
        assert published.keys() == step["poses"].keys(), f"tick {tick}"
        for turtle, expected in step["poses"].items():
            assert published[turtle] == pytest.approx(expected, abs=FLOAT32_SLACK), (
                f"tick {tick}, {turtle}: got {published[turtle]}, real turtlesim {expected}"
            )


def test_traces_cover_every_flavour_and_fidelity_point() -> None:
    """The traces exercise what differs from a naive simulator, in every flavour."""
    names = {path.stem for path in TRACES.glob("*.json")}
    assert names == {"holonomic", "not_holonomic", "teleports", "timeout"}
    flavours = {
        f for path in TRACES.glob("*.json") for f in json.loads(path.read_text())["flavours"]
    }
    assert flavours == {"1", "2", "jazzy"}
