"""Scripted input sequences for the vehicle's pilot, run by the Python :class:`Pilot` here
(tests/vehicle_agent/test_pilot.py) and by ``pilot.js`` in Chromium (e2e/test_pilot_js.py): both
must answer every input with the same event records, and the same wake-up for the next tick.

A step is ``(kind, t, args)``, ``t`` the vehicle's clock in seconds: ``goal`` (the goal message
as the relay sends it), ``stop`` (), ``mode`` (mode, operator), ``drive`` (seq, linear,
angular), ``pose`` (x, y, theta), ``tick`` (), ``new_link`` (), ``halt`` ().

Every sequence runs with every profile on every robot preset (:data:`ROBOTS`): turtlesim's limits
change nothing, a Burger's clamp and ramp the commands (the last sequences are about that).
"""

from __future__ import annotations

from typing import Any

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.control import PROFILES, TERRAIN_CENTRE, for_robot
from app.protocol.robot import PRESETS
from vehicle_agent.control import Pose
from vehicle_agent.pilot import Pilot

Step = tuple[str, float, list[Any]]

# The relay's clock runs this far from the vehicle's (ms): the gate never compares them directly.
RELAY_CLOCK_MS = 5_000_000.0


def goal(seq: int, t: float, x: float = 100.0, y: float = 120.0, late_s: float = 0.0) -> Step:
    """The relay's goal ``seq``, received at ``t``: sent at ``t`` on the relay's clock, or
    ``late_s`` earlier (it waited that much longer on the way)."""
    message = {
        "type": "goal",
        "seq": seq,
        "op": "face",
        "x": x,
        "y": y,
        "w": 640,
        "h": 480,
        "t": RELAY_CLOCK_MS + (t - late_s) * 1000,
        "frame": 100 + seq,
    }
    return ("goal", t, [message])


CENTRE_POSE: Step = ("pose", 0.0, [TERRAIN_CENTRE, TERRAIN_CENTRE, 0.0])


def at(step: Step, t: float) -> Step:
    """``step`` at another time."""
    return (step[0], t, step[2])


SEQUENCES: dict[str, list[Step]] = {
    "goals steer and poses keep steering": [
        CENTRE_POSE,
        goal(1, 0.1),
        at(CENTRE_POSE, 0.116),
        at(CENTRE_POSE, 0.132),
        at(CENTRE_POSE, 0.2),
        goal(2, 0.21, x=600.0, y=300.0),
        ("tick", 0.25, []),
        at(CENTRE_POSE, 0.3),
    ],
    "old and stale goals are dropped": [
        CENTRE_POSE,
        goal(3, 0.1),
        goal(2, 0.15),
        goal(3, 0.2),
        goal(4, 0.3, late_s=1.0),
        goal(5, 0.4),
    ],
    "the goal timeout stops the turtle": [
        CENTRE_POSE,
        goal(1, 0.1),
        ("tick", 0.5, []),
        ("tick", 0.79, []),
        ("tick", 0.8, []),
        ("tick", 0.85, []),
        ("tick", 2.5, []),
        ("tick", 2.7, []),
        ("tick", 12.0, []),
    ],
    "the relay's stop": [CENTRE_POSE, goal(1, 0.1), ("stop", 0.2, []), ("stop", 0.3, [])],
    "take over: goals dropped, drive steers, the dead-man stops, hand back": [
        CENTRE_POSE,
        goal(1, 0.1),
        ("mode", 0.2, ["manual", "ann"]),
        goal(2, 0.25),
        ("drive", 0.3, [1, 0.5, -1.0]),
        goal(3, 0.35),
        ("drive", 0.4, [1, 1.0, 1.0]),
        ("tick", 0.45, []),
        ("tick", 0.58, []),
        ("tick", 0.599, []),
        ("tick", 0.6, []),
        ("tick", 0.75, []),
        ("drive", 0.8, [2, 0.0, 0.0]),
        ("mode", 0.9, ["manual", "ann"]),
        ("mode", 1.0, ["auto", None]),
        ("drive", 1.05, [3, 1.0, 0.0]),
        goal(4, 1.1),
    ],
    "a lost link halts, in either mode": [
        CENTRE_POSE,
        goal(1, 0.1),
        ("halt", 0.2, []),
        ("halt", 0.25, []),
        ("mode", 0.3, ["manual", "bob"]),
        ("drive", 0.35, [1, 0.0, 1.0]),
        ("halt", 0.4, []),
        goal(2, 0.5),
    ],
    "a new link starts the goal and drive seq again": [
        CENTRE_POSE,
        goal(7, 0.1),
        ("new_link", 0.2, []),
        goal(1, 0.3),
        ("mode", 0.4, ["manual", "ann"]),
        ("drive", 0.45, [5, 0.0, 1.0]),
        ("new_link", 0.5, []),
        ("drive", 0.55, [1, 0.0, 1.0]),
        ("mode", 0.6, ["manual", "ann"]),
        ("drive", 0.65, [1, 0.0, 1.0]),
    ],
    "the clock-driven and searching profiles on a long run": [
        CENTRE_POSE,
        goal(1, 0.1),
        *[("tick", round(0.1 + 0.05 * k, 2), []) for k in range(1, 60)],
        at(CENTRE_POSE, 3.1),
    ],
    "an operator's commands ramped, then stopped at once": [
        CENTRE_POSE,
        ("mode", 0.0, ["manual", "ann"]),
        ("drive", 0.1, [1, 1.0, -1.0]),
        ("tick", 0.15, []),
        ("drive", 0.2, [2, 1.0, -1.0]),
        ("tick", 0.25, []),
        ("drive", 0.3, [3, -1.0, 1.0]),
        ("tick", 0.33, []),
        ("tick", 0.4, []),
        ("drive", 0.4, [4, -1.0, 1.0]),
        ("tick", 0.45, []),
        ("drive", 0.5, [5, 0.0, 0.0]),
        ("tick", 0.55, []),
        ("drive", 0.6, [6, 0.4, -0.2]),
        *[("tick", round(0.6 + 0.05 * k, 2), []) for k in range(1, 9)],
        ("halt", 1.02, []),
    ],
    "the autopilot ramped toward a target far behind": [
        CENTRE_POSE,
        goal(1, 0.1, x=0.0, y=470.0),
        *[
            step
            for k in range(1, 16)
            for step in (("tick", round(0.1 + 0.05 * k, 2), []), at(CENTRE_POSE, 0.12 + 0.05 * k))
        ],
        goal(2, 0.9, x=600.0, y=20.0),
        ("tick", 0.95, []),
        at(CENTRE_POSE, 1.0),
        ("stop", 1.02, []),
        ("tick", 1.05, []),
    ],
}

# The robots every sequence runs on.
ROBOTS = tuple(PRESETS)


def pilot(profile: str, robot: str = "turtlesim") -> Pilot:
    """The pilot each sequence runs against, built as the agent builds it: the profile fitted to
    the robot, its limits, the protocol's dead-man, tick and freshness rule (the page gets them
    through its config)."""
    described = PRESETS[robot]
    return Pilot(for_robot(PROFILES[profile], described), limits=described.limits)


def feed(driven: Pilot, kind: str, t: float, args: list[Any]) -> list[ev.AnyEvent]:
    """One step's input to ``driven``; its answer."""
    match kind:
        case "goal":
            return list(driven.goal(channels.Goal.model_validate(args[0]), t))
        case "stop":
            return list(driven.stop(t))
        case "mode":
            return list(driven.mode_change(args[0], args[1], t))
        case "drive":
            return list(driven.drive(args[0], args[1], args[2], t))
        case "pose":
            return list(driven.pose(Pose(*args), t))
        case "tick":
            return list(driven.tick(t))
        case "new_link":
            return list(driven.new_link(t))
        case "halt":
            return list(driven.halt(t))
    raise ValueError(f"no such input {kind!r}")


def run(steps: list[Step], profile: str, robot: str = "turtlesim") -> list[Any]:
    """Each step's answer: its records (log-line objects), the seconds to the next tick, the
    mode and the operator."""
    driven = pilot(profile, robot)
    out: list[Any] = []
    for kind, t, args in steps:
        records = [ev.record(event) for event in feed(driven, kind, t, args)]
        out.append([records, driven.next_tick(t), driven.mode, driven.operator])
    return out
