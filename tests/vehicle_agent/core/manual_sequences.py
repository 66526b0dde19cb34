"""Scripted event sequences for the manual override at the vehicle, run by the Python
:class:`ManualDrive` here and by ``manual.js`` in e2e/test_manual_js.py: both must answer alike."""

from __future__ import annotations

from typing import Any

from app.protocol.control import DEADMAN_S
from vehicle_agent.core.control import Profile
from vehicle_agent.core.manual import ManualDrive

# (kind, t, args): "mode" (mode, operator), "drive" (seq, linear, angular), "tick" ().
Event = tuple[str, float, list[Any]]

SEQUENCES: dict[str, list[Event]] = {
    "drive in auto is ignored": [("drive", 0.0, [1, 1.0, 0.0]), ("tick", 1.0, [])],
    "take over, drive, release": [
        ("mode", 0.0, ["manual", "ann"]),
        ("drive", 0.1, [1, 0.0, 1.0]),
        ("drive", 0.2, [2, 0.0, 1.0]),
        ("tick", 0.3, []),
        ("drive", 0.35, [3, 0.0, 0.0]),
        ("tick", 1.0, []),
    ],
    "dead-man after the last command": [
        ("mode", 0.0, ["manual", "ann"]),
        ("drive", 0.1, [1, 0.5, -0.5]),
        ("tick", 0.1 + DEADMAN_S - 0.01, []),
        ("tick", 0.1 + DEADMAN_S, []),
        ("tick", 0.1 + DEADMAN_S + 0.05, []),
    ],
    "old and repeated seq dropped, out-of-range clamped": [
        ("mode", 0.0, ["manual", "ann"]),
        ("drive", 0.1, [5, 3.0, -7.0]),
        ("drive", 0.15, [4, 0.0, 1.0]),
        ("drive", 0.2, [5, 0.0, 1.0]),
    ],
    "hand back stops, a new operator starts at seq 1": [
        ("mode", 0.0, ["manual", "ann"]),
        ("drive", 0.1, [9, 1.0, 0.0]),
        ("mode", 0.2, ["auto", None]),
        ("drive", 0.25, [10, 1.0, 0.0]),
        ("mode", 0.3, ["auto", None]),
        ("mode", 0.4, ["manual", "bob"]),
        ("drive", 0.5, [1, -1.0, 0.0]),
    ],
}


def run(events: list[Event], profile: Profile) -> list[Any]:
    """Each event's answer: the Twist as [linear, angular] or None, then manual, operator and
    the seconds to the dead-man (the protocol's dead-man time, as the vehicles get it)."""
    drive = ManualDrive(profile, DEADMAN_S)
    out: list[Any] = []
    for kind, t, args in events:
        if kind == "mode":
            twist = drive.set_mode(args[0], args[1])
        elif kind == "drive":
            twist = drive.drive(*args, t)
        else:
            twist = drive.tick(t)
        answer = None if twist is None else [twist.linear_x, twist.angular_z]
        out.append([answer, drive.manual, drive.operator, drive.until_deadman(t)])
    return out
