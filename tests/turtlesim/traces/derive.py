"""How the turtlesim traces in this folder were derived: by hand, from docs/turtlesim-facts.md.

Run by hand (``python3 tests/turtlesim/traces/derive.py``) to rewrite the JSON files. It never
imports the project's simulator: every tick below is the arithmetic of facts F5-F12 written out
for one scenario, so a trace says what the real turtlesim_node publishes, not what our code does.
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

HERE = Path(__file__).resolve().parent
DT = 0.016  # F3


def f32(value: float) -> float:
    """A float32 field (F1, F10, F14)."""
    return float(struct.unpack("f", struct.pack("f", value))[0])


SIZE = f32(499 / 45)  # F1
CENTRE = f32(SIZE / 2)  # F2


def wrap(theta: float) -> float:
    """F7's wrap into [-pi, pi)."""
    return theta - 2 * math.pi * math.floor((theta + math.pi) / (2 * math.pi))


def clamp(value: float) -> float:
    """F9."""
    return min(max(value, 0.0), SIZE)


def pose(x: float, y: float, theta: float, vx: float, vy: float, w: float) -> list[float]:
    """F10: what one tick publishes."""
    return [x, y, theta, math.hypot(vx, vy), w]


def twist(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> dict[str, object]:
    return {"op": "cmd_vel", "turtle": "turtle1", "linear": {"x": x, "y": y}, "angular_z": z}


def holonomic() -> dict[str, object]:
    """noetic and humble: linear.y moves sideways, linear_velocity is a speed (F8, F10, F11)."""
    x, y, th = CENTRE, CENTRE, 0.0
    steps = []
    # Ticks 1-3: linear.y = 1 alone: theta stays 0, so y grows by 0.016 a tick.
    for k in range(3):
        y = y + 1.0 * DT
        steps.append(
            {
                "before": [twist(y=1.0)] if k == 0 else [],
                "poses": {"turtle1": pose(x, y, th, 0, 1, 0)},
            }
        )
    # Ticks 4-5: (0.6, 0.8): speed 1.0.
    for k in range(2):
        x, y = x + 0.6 * DT, y + 0.8 * DT
        steps.append(
            {
                "before": [twist(0.6, 0.8)] if k == 0 else [],
                "poses": {"turtle1": pose(x, y, th, 0.6, 0.8, 0)},
            }
        )
    # Tick 6: backwards: linear_velocity is still +1.
    x = x - 1.0 * DT
    steps.append({"before": [twist(-1.0)], "poses": {"turtle1": pose(x, y, th, -1.0, 0, 0)}})
    # Ticks 7-9: forward while turning: rotate first, then move along the new heading (F7, F8).
    for k in range(3):
        th = wrap(th + 1.0 * DT)
        x, y = x + math.cos(th) * DT, y + math.sin(th) * DT
        steps.append(
            {
                "before": [twist(1.0, 0.0, 1.0)] if k == 0 else [],
                "poses": {"turtle1": pose(x, y, th, 1, 0, 1)},
            }
        )
    # Ticks 10-11: sideways while turning: vy along the rotated left-hand direction.
    for k in range(2):
        th = wrap(th + 1.0 * DT)
        x, y = x - math.sin(th) * DT, y + math.cos(th) * DT
        steps.append(
            {
                "before": [twist(0.0, 1.0, 1.0)] if k == 0 else [],
                "poses": {"turtle1": pose(x, y, th, 0, 1, 1)},
            }
        )
    return {"flavours": ["1", "2"], "steps": steps}


def not_holonomic() -> dict[str, object]:
    """turtlesim_msgs (Jazzy+), parameter holonomic unset: linear.y is not stored (F11)."""
    x, y, th = CENTRE, CENTRE, 0.0
    steps = []
    for k in range(2):
        steps.append(
            {
                "before": [twist(y=1.0)] if k == 0 else [],
                "poses": {"turtle1": pose(x, y, th, 0, 0, 0)},
            }
        )
    x = x + 0.6 * DT
    steps.append({"before": [twist(0.6, 0.8)], "poses": {"turtle1": pose(x, y, th, 0.6, 0, 0)}})
    return {"flavours": ["jazzy"], "steps": steps}


def teleports() -> dict[str, object]:
    """Queued teleports and spawns, applied and clamped by the next tick (F5, F12, F14)."""
    steps = []
    # Tick 1: teleport_absolute(1, 2, 0.5) with linear.x = 1: jump, then move 0.016 along 0.5.
    x, y, th = 1.0, 2.0, 0.5
    x, y = x + math.cos(th) * DT, y + math.sin(th) * DT
    steps.append(
        {
            "before": [
                twist(1.0),
                {"op": "teleport_absolute", "turtle": "turtle1", "x": 1.0, "y": 2.0, "theta": 0.5},
            ],
            "poses": {"turtle1": pose(x, y, th, 1, 0, 0)},
        }
    )
    # Tick 2: teleport_relative(linear 1, angular pi/2 as float32): turn, then jump along the
    # new heading; then the tick's own 0.016 m along it.
    th = th + f32(math.pi / 2)
    x, y = x + math.cos(th) * 1.0, y + math.sin(th) * 1.0
    th = wrap(th)
    x, y = x + math.cos(th) * DT, y + math.sin(th) * DT
    steps.append(
        {
            "before": [
                {
                    "op": "teleport_relative",
                    "turtle": "turtle1",
                    "linear": 1.0,
                    "angular": math.pi / 2,
                }
            ],
            "poses": {"turtle1": pose(x, y, th, 1, 0, 0)},
        }
    )
    # Tick 3: teleport_absolute(-1, 20, 4) and a stop: y is cut to the top at once, x is
    # clamped by the tick, theta 4 is wrapped by the tick.
    x, y, th = -1.0, min(20.0, SIZE), 4.0
    th = wrap(th)
    x, y = clamp(x), clamp(y)
    steps.append(
        {
            "before": [
                twist(),
                {
                    "op": "teleport_absolute",
                    "turtle": "turtle1",
                    "x": -1.0,
                    "y": 20.0,
                    "theta": 4.0,
                },
            ],
            "poses": {"turtle1": pose(x, y, th, 0, 0, 0)},
        }
    )
    # Tick 4: teleport_relative(-2, 0) backwards from the corner: y overshoots and is clamped.
    x, y = x + math.cos(th) * -2.0, y + math.sin(th) * -2.0
    x, y = clamp(x), clamp(y)
    steps.append(
        {
            "before": [
                {"op": "teleport_relative", "turtle": "turtle1", "linear": -2.0, "angular": 0.0}
            ],
            "poses": {"turtle1": pose(x, y, th, 0, 0, 0)},
        }
    )
    # Tick 5: four requests in one gap, applied in order with no clamp between them: relative
    # +1, absolute (3, 3, 0), relative +10 (out to x = 13), relative -5 (back to x = 8).
    x, y, th = 3.0 + 10.0 - 5.0, 3.0, 0.0
    steps.append(
        {
            "before": [
                {"op": "teleport_relative", "turtle": "turtle1", "linear": 1.0, "angular": 0.0},
                {"op": "teleport_absolute", "turtle": "turtle1", "x": 3.0, "y": 3.0, "theta": 0.0},
                {"op": "teleport_relative", "turtle": "turtle1", "linear": 10.0, "angular": 0.0},
                {"op": "teleport_relative", "turtle": "turtle1", "linear": -5.0, "angular": 0.0},
            ],
            "poses": {"turtle1": pose(x, y, th, 0, 0, 0)},
        }
    )
    # Tick 6: spawn(12, -3, 7, "leo") outside the world: its first pose is clamped and wrapped.
    steps.append(
        {
            "before": [{"op": "spawn", "name": "leo", "x": 12.0, "y": -3.0, "theta": 7.0}],
            "poses": {
                "turtle1": pose(8.0, 3.0, 0.0, 0, 0, 0),
                "leo": pose(SIZE, 0.0, wrap(7.0), 0, 0, 0),
            },
        }
    )
    return {"flavours": ["1", "2", "jazzy"], "steps": steps}


def timeout() -> dict[str, object]:
    """F6: a command given at t0 is obeyed while now - t0 <= 1.0 s; tick 63 (1.008 s) stops."""
    x, y, th = CENTRE, CENTRE, 0.0
    steps = []
    for k in range(1, 65):
        now = k * DT
        if now > 1.0:
            steps.append({"before": [], "poses": {"turtle1": pose(x, y, th, 0, 0, 0)}})
            continue
        th = wrap(th + 0.25 * DT)
        x, y = x + math.cos(th) * 0.5 * DT, y + math.sin(th) * 0.5 * DT
        steps.append(
            {
                "before": [twist(0.5, 0.0, 0.25)] if k == 1 else [],
                "poses": {"turtle1": pose(x, y, th, 0.5, 0, 0.25)},
            }
        )
    return {"flavours": ["1", "2", "jazzy"], "steps": steps}


NOTE = (
    "Derived by hand from docs/turtlesim-facts.md by tests/turtlesim/traces/derive.py (which "
    "never imports the simulator). Clock starts at 0 and advances 0.016 s before each tick; the "
    "'before' actions happen at the clock time of the previous tick. A pose is [x, y, theta, "
    "linear_velocity, angular_velocity] as published after that tick, in double precision: the "
    "wire rounds to float32 (F10)."
)

if __name__ == "__main__":
    for name, build in (
        ("holonomic", holonomic),
        ("not_holonomic", not_holonomic),
        ("teleports", teleports),
        ("timeout", timeout),
    ):
        trace = {"note": NOTE, "derivation": build.__doc__, **build()}
        (HERE / f"{name}.json").write_text(json.dumps(trace, indent=1) + "\n")
