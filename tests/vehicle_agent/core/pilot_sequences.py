"""Scripted input sequences for the vehicle's pilot, run by the Python :class:`Pilot` here
(tests/vehicle_agent/core/test_pilot.py) and by ``pilot.js`` in Chromium (e2e/test_pilot_js.py):
both must answer every input with the same event records, and the same wake-up for the next tick.

A step is ``(kind, t, args)``, ``t`` the vehicle's clock in seconds: ``frame`` (the number of a
frame the vehicle's own camera took at ``t``), ``goal`` (the goal message as the relay sends it),
``stop`` (), ``mode`` (mode, operator), ``drive`` (seq, linear, angular), ``pose`` (x, y, theta),
``tick`` (), ``new_link`` (), ``halt`` ().

Every sequence runs with every profile on every robot preset (:data:`ROBOTS`): turtlesim's limits
change nothing, a Burger's clamp and ramp the commands (the last sequences are about that); the
onboard profile sees through the robot's camera (none on a turtlesim: it only searches).
"""

from __future__ import annotations

from typing import Any

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.control import PROFILES, TERRAIN_CENTRE
from app.protocol.robot import PRESETS
from vehicle_agent.core.control import Pose
from vehicle_agent.core.pilot import Pilot

Step = tuple[str, float, list[Any]]

# The relay's clock runs this far from the vehicle's (ms): the gate never compares them directly.
RELAY_CLOCK_MS = 5_000_000.0


# A stamp ahead of every vehicle's wall clock by far more than the skew the gate allows (the
# year 2500): the twins judge it against their real clocks alike.
FAR_FUTURE_MS = 16_725_225_600_000.0

# A face's real height as the operations spec declares it (goals with a box carry it).
FACE_HEIGHT_M = 0.24


def goal(
    seq: int,
    t: float,
    x: float = 100.0,
    y: float = 120.0,
    late_s: float = 0.0,
    box_h: float | None = None,
    locked: bool | None = None,
    stamp_ms: float | None = None,
) -> Step:
    """The relay's goal ``seq``, received at ``t``: sent at ``t`` on the relay's clock, or
    ``late_s`` earlier (it waited that much longer on the way), found in frame ``100 + seq``;
    with a face's box ``box_h`` pixels high when given, and ``locked`` when given (an older
    relay says nothing); ``stamp_ms`` replaces the relay's stamp."""
    message: dict[str, Any] = {
        "type": "goal",
        "seq": seq,
        "op": "face",
        "x": x,
        "y": y,
        "w": 640,
        "h": 480,
        "t": RELAY_CLOCK_MS + (t - late_s) * 1000 if stamp_ms is None else stamp_ms,
        "frame": 100 + seq,
    }
    if box_h is not None:
        message |= {"boxW": box_h * 0.9, "boxH": box_h, "targetHeightM": FACE_HEIGHT_M}
    if locked is not None:
        message["locked"] = locked
    return ("goal", t, [message])


def taken(seq: int, t: float) -> Step:
    """The vehicle's camera took the frame goal ``seq`` will be found in at ``t``."""
    return ("frame", t, [100 + seq])


CENTRE_POSE: Step = ("pose", 0.0, [TERRAIN_CENTRE, TERRAIN_CENTRE, 0.0])


def at(step: Step, t: float) -> Step:
    """``step`` at another time."""
    return (step[0], t, step[2])


def odom(t: float, theta: float, x: float = 1.0, y: float = 3.0) -> Step:
    """A robot's odometry pose at ``t`` (its room's metres)."""
    return ("pose", t, [x, y, theta])


def poses(start: float, end: float, every: float, theta: float = 0.0) -> list[Step]:
    """Odometry every ``every`` s from ``start`` to ``end``, the robot not turning."""
    count = round((end - start) / every)
    return [odom(round(start + k * every, 6), theta) for k in range(count + 1)]


SEQUENCES: dict[str, list[Step]] = {
    "goals steer and poses keep steering": [
        CENTRE_POSE,
        goal(1, 0.1),
        at(CENTRE_POSE, 0.116),
        at(CENTRE_POSE, 0.132),
        at(CENTRE_POSE, 0.2),
        goal(2, 0.21, x=600.0, y=300.0, box_h=60.0, locked=True),
        ("tick", 0.25, []),
        at(CENTRE_POSE, 0.3),
        goal(3, 0.31, locked=False),
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
    "goals from the future are refused and hold back no real goal": [
        CENTRE_POSE,
        goal(1, 0.1),
        goal(2**40, 0.12),  # a seq no link can have reached
        goal(2, 0.15, x=600.0),
        goal(3, 0.2, stamp_ms=FAR_FUTURE_MS),  # stamped ahead of any vehicle's clock
        goal(4, 0.25, x=40.0),
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
    # A face with its box (the onboard law's range): right of centre and far, then turned to,
    # then centred at the standoff, then too close.
    "a face's box: turn to it, drive to the standoff, back off": [
        odom(0.0, 0.0),
        goal(1, 0.1, x=480.0, y=240.0, box_h=40.0),
        odom(0.13, -0.1),
        odom(0.16, -0.2),
        goal(2, 0.2, x=321.0, y=240.0, box_h=40.0),
        odom(0.26, -0.2),
        goal(3, 0.3, x=320.0, y=240.0, box_h=111.0),
        goal(4, 0.4, x=330.0, y=250.0, box_h=200.0),
        goal(5, 0.5, x=40.0, y=250.0, box_h=60.0),
        ("tick", 0.55, []),
    ],
    # Goals whose frames were taken 0.15 s before they arrived, the robot turning meanwhile:
    # their bearings are taken from the heading it had then, not on arrival.
    "a face's bearing from the heading its frame was taken at": [
        odom(0.0, 0.0),
        odom(0.05, 0.0),
        odom(0.1, -0.05),
        odom(0.15, -0.1),
        taken(1, 0.05),
        goal(1, 0.2, x=480.0, y=240.0, box_h=60.0),
        odom(0.21, -0.15),
        odom(0.25, -0.2),
        taken(2, 0.16),
        goal(2, 0.3, x=400.0, y=240.0, box_h=60.0),
        odom(0.31, -0.25),
        # Taken before the oldest heading remembered: the oldest one stands in for it.
        taken(3, -5.0),
        goal(3, 0.4, x=330.0, y=240.0, box_h=60.0),
        goal(4, 0.5, x=330.0, y=240.0, box_h=60.0),
    ],
    # A face that walks left round the robot, 0.05 rad a frame every 0.1 s (frames taken 0.1 s
    # before their goals arrive), the robot turning: it is turned with as well as toward; then
    # one seen far off to the right at once (another face, not a walk).
    "a walking face is turned with, a jump is not a walk": [
        odom(0.0, 0.0),
        *[
            step
            for k in range(1, 6)
            for step in (
                odom(round(0.1 * k, 2), 0.02 * k),
                taken(k, round(0.1 * k - 0.09, 2)),
                goal(k, round(0.1 * k + 0.01, 2), x=320.0 - 40.0 * k, box_h=80.0),
            )
        ],
        odom(0.58, 0.12),
        taken(6, 0.52),
        goal(6, 0.61, x=600.0, box_h=80.0),
        odom(0.66, 0.1),
    ],
    # The face leaves by the left: a search turns left, and finds it again.
    "a face lost on the left is searched for and found": [
        odom(0.0, 0.0),
        goal(1, 0.12, x=60.0, y=200.0, box_h=80.0),
        *poses(0.15, 1.23, 0.06, theta=0.3),
        ("tick", 1.21, []),
        goal(2, 1.25, x=500.0, y=200.0, box_h=80.0),
        odom(1.3, 0.3),
    ],
    # The face leaves by the right and stays away: the search turns right until its time runs
    # out, then the vehicle stops.
    "a face lost on the right: the search runs out and stops": [
        odom(0.0, 0.0),
        goal(1, 0.11, x=600.0, y=200.0, box_h=80.0),
        *poses(0.2, 8.0, 0.2, theta=-0.5),
        *[("tick", 8.0 + 0.5 * k, []) for k in range(1, 5)],
        goal(2, 10.5, x=620.0, y=200.0, box_h=80.0),
        ("stop", 10.6, []),
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
    """The pilot each sequence runs against, built as the agent builds it: the profile and the
    robot (the pilot fits the one to the other), the protocol's dead-man, tick and freshness
    rule (the page gets them through its config)."""
    return Pilot(PROFILES[profile], robot=PRESETS[robot])


def feed(driven: Pilot, kind: str, t: float, args: list[Any]) -> list[ev.AnyEvent]:
    """One step's input to ``driven``; its answer."""
    match kind:
        case "frame":
            driven.frame(args[0], t)
            return []
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
    mode, the operator and the search status the pose tells the client."""
    driven = pilot(profile, robot)
    out: list[Any] = []
    for kind, t, args in steps:
        records = [ev.record(event) for event in feed(driven, kind, t, args)]
        out.append([records, driven.next_tick(t), driven.mode, driven.operator, driven.search])
    return out
