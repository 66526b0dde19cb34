"""Data-channel messages, valid and not, that both validators must judge alike.

Each sample is what one side receives on one channel, as the text on the wire. An invalid one
names the field its error must mention (None when the message is refused as a whole).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from app.protocol.rooms import Role


@dataclass(frozen=True)
class Sample:
    """One message text received by ``role`` on channel ``label``."""

    label: str
    role: Role
    text: str
    valid: bool
    field: str | None = None


GOAL: dict[str, Any] = {
    "type": "goal", "seq": 3, "op": "face", "x": 100.5, "y": 240, "w": 640, "h": 480, "t": 1.7e12,
}  # fmt: skip
POSE: dict[str, Any] = {"type": "pose", "x": 5.5, "y": 1, "theta": -3.1, "t": 17.0}
DETECTIONS: dict[str, Any] = {
    "type": "detections", "op": "face", "boxes": [[1, 2, 30, 40]], "target": {"x": 16, "y": 22},
    "w": 640, "h": 480, "ms": 12.5, "goalsPerS": 19.5,
}  # fmt: skip
OPS: dict[str, Any] = {
    "type": "ops", "ops": [{"id": "face", "label": "Face", "description": "Haar"}],
    "current": "face",
}  # fmt: skip
STATE: dict[str, Any] = {"type": "state", "piloting": True, "op": "face", "vehicle": None}
FRAME_TIMES: dict[str, Any] = {
    "type": "frameTimes", "frames": [{"frame": 41, "t": 1.7e12}, {"frame": 42, "t": 1.7e12 + 33}],
}  # fmt: skip


def _with(base: dict[str, Any], **changes: Any) -> str:
    return json.dumps({**base, **changes})


def _without(base: dict[str, Any], key: str) -> str:
    return json.dumps({k: v for k, v in base.items() if k != key})


A, S, C = "autopilot", "autopilot-state", "control"

SAMPLES: list[Sample] = [
    # relay -> vehicle on `autopilot`
    Sample(A, "vehicle", json.dumps(GOAL), True),
    Sample(A, "vehicle", _with(GOAL, frame=12, extra="newer relays may add fields"), True),
    Sample(A, "vehicle", _with(GOAL, frame=None), True),
    Sample(A, "vehicle", _with(GOAL, x="left"), False, "x"),
    Sample(A, "vehicle", _with(GOAL, x=True), False, "x"),
    Sample(A, "vehicle", _with(GOAL, w=0), False, "w"),
    Sample(A, "vehicle", _with(GOAL, h=-480), False, "h"),
    # The target's box and real height (the onboard law's range).
    Sample(A, "vehicle", _with(GOAL, boxW=60, boxH=64.5, targetHeightM=0.24), True),
    Sample(A, "vehicle", _with(GOAL, boxH=0), False, "boxH"),
    Sample(A, "vehicle", _with(GOAL, boxW=-3), False, "boxW"),
    Sample(A, "vehicle", _with(GOAL, boxH="64"), False, "boxH"),
    Sample(A, "vehicle", _with(GOAL, boxH=1e9), False, "boxH"),
    Sample(A, "vehicle", _with(GOAL, targetHeightM=0), False, "targetHeightM"),
    Sample(A, "vehicle", _with(GOAL, targetHeightM=1e6), False, "targetHeightM"),
    # Whether the target is the operator's lock (a boolean; absent: unlocked).
    Sample(A, "vehicle", _with(GOAL, locked=True), True),
    Sample(A, "vehicle", _with(GOAL, locked="yes"), False, "locked"),
    Sample(A, "vehicle", _with(GOAL, locked=1), False, "locked"),
    Sample(A, "vehicle", _with(GOAL, locked=None), False, "locked"),
    Sample(A, "vehicle", _with(GOAL, w=640.5), False, "w"),
    Sample(A, "vehicle", _with(GOAL, seq=0), False, "seq"),
    Sample(A, "vehicle", _with(GOAL, seq="1"), False, "seq"),
    Sample(A, "vehicle", _with(GOAL, op=""), False, "op"),
    Sample(A, "vehicle", _with(GOAL, op=7), False, "op"),
    Sample(A, "vehicle", _with(GOAL, frame=-1), False, "frame"),
    Sample(A, "vehicle", _without(GOAL, "seq"), False, "seq"),
    Sample(A, "vehicle", _without(GOAL, "t"), False, "t"),
    Sample(A, "vehicle", json.dumps(GOAL).replace('"x": 100.5', '"x": NaN'), False),
    Sample(A, "vehicle", json.dumps(GOAL).replace('"y": 240', '"y": Infinity'), False),
    Sample(A, "vehicle", json.dumps(GOAL).replace('"y": 240', '"y": -Infinity'), False),
    Sample(A, "vehicle", '{"type": "stop"}', True),
    Sample(A, "vehicle", '{"type": "error", "reason": "bad pose", "ref": "pose"}', True),
    Sample(A, "vehicle", '{"type": "error", "reason": "no ref"}', True),
    Sample(A, "vehicle", '{"type": "error", "ref": "pose"}', False, "reason"),
    Sample(A, "vehicle", json.dumps(POSE), False),  # the vehicle never receives a pose
    Sample(A, "vehicle", '{"type": "warp"}', False),
    Sample(A, "vehicle", '{"type": 3}', False),
    Sample(A, "vehicle", "[1, 2]", False),
    Sample(A, "vehicle", "null", False),
    Sample(A, "vehicle", "not json {", False),
    # vehicle -> relay on `autopilot`
    Sample(A, "relay", json.dumps(POSE), True),
    Sample(A, "relay", _without(POSE, "t"), True),
    Sample(A, "relay", _with(POSE, t=None), True),
    Sample(A, "relay", _with(POSE, theta="up"), False, "theta"),
    Sample(A, "relay", _without(POSE, "y"), False, "y"),
    Sample(A, "relay", json.dumps(GOAL), False),
    # Capture times ride the lossy state channel only.
    Sample(A, "relay", json.dumps(FRAME_TIMES), False),
    # vehicle -> relay on `autopilot-state`
    Sample(S, "relay", json.dumps(POSE), True),
    Sample(S, "relay", json.dumps(FRAME_TIMES), True),
    Sample(S, "relay", _with(FRAME_TIMES, frames=[]), False, "frames"),
    Sample(S, "relay", _with(FRAME_TIMES, frames=[{"frame": 1, "t": 2}] * 65), False, "frames"),
    Sample(S, "relay", _with(FRAME_TIMES, frames=[{"frame": -1, "t": 2}]), False, "frames.0.frame"),
    Sample(S, "relay", _with(FRAME_TIMES, frames=[{"frame": 1}]), False, "frames.0.t"),
    Sample(S, "relay", _with(FRAME_TIMES, frames=[{"frame": 1, "t": "now"}]), False, "frames.0.t"),
    Sample(S, "relay", _with(FRAME_TIMES, frames={"frame": 1, "t": 2}), False, "frames"),
    Sample(S, "relay", json.dumps(FRAME_TIMES).replace("1700000000000.0", "NaN", 1), False),
    Sample(S, "vehicle", json.dumps(FRAME_TIMES), False),
    # client -> relay on `control`
    Sample(C, "relay", '{"type": "getOps"}', True),
    Sample(C, "relay", '{"type": "start"}', True),
    Sample(C, "relay", '{"type": "stop"}', True),
    Sample(C, "relay", '{"type": "setOp", "op": "fire"}', True),
    Sample(C, "relay", '{"type": "setOp"}', False, "op"),
    Sample(C, "relay", '{"type": "setOp", "op": ["fire"]}', False, "op"),
    Sample(C, "relay", '{"type": "setOp", "op": "' + "x" * 65 + '"}', False, "op"),
    Sample(C, "relay", json.dumps(POSE), False),
    Sample(C, "relay", '{"type": "lock", "x": 470.5, "y": 230}', True),
    Sample(C, "relay", '{"type": "lock", "x": 470.5}', False, "y"),
    Sample(C, "relay", '{"type": "lock", "x": "left", "y": 230}', False, "x"),
    Sample(C, "relay", '{"type": "unlock"}', True),
    Sample(C, "relay", '{"type": "stopRobot"}', True),
    Sample(C, "relay", '{"type": "robotStopped", "by": "ann", "reason": "pressed"}', False),
    Sample(C, "relay", '{"type": "lockState", "state": "none"}', False),
    # relay -> client on `control`
    Sample(C, "client", json.dumps(OPS), True),
    Sample(C, "client", _without(OPS, "current"), True),
    Sample(C, "client", _with(OPS, ops={"id": "face"}), False, "ops"),
    Sample(
        C, "client", _with(OPS, ops=[{"id": "face", "label": "Face"}]), False, "ops.0.description"
    ),
    Sample(C, "client", json.dumps(STATE), True),
    Sample(C, "client", _with(STATE, piloting="yes"), False, "piloting"),
    Sample(C, "client", _with(STATE, piloting=1), False, "piloting"),
    Sample(C, "client", _without(STATE, "vehicle"), False, "vehicle"),
    Sample(C, "client", json.dumps(DETECTIONS), True),
    Sample(C, "client", _with(DETECTIONS, boxes=[], target=None), True),
    Sample(C, "client", _with(DETECTIONS, boxes=[[1, 2, 3]]), False, "boxes"),
    Sample(C, "client", _with(DETECTIONS, boxes=[[1, 2, 3, "4"]]), False, "boxes"),
    Sample(C, "client", _with(DETECTIONS, target={"x": 1}), False, "target"),
    Sample(C, "client", _with(DETECTIONS, target=[1, 2]), False, "target"),
    Sample(C, "client", _with(DETECTIONS, ms=-1), False, "ms"),
    Sample(C, "client", _without(DETECTIONS, "goalsPerS"), False, "goalsPerS"),
    Sample(C, "client", json.dumps(POSE), True),
    Sample(C, "client", json.dumps(FRAME_TIMES), True),
    Sample(
        C, "client", _with(FRAME_TIMES, frames=[{"frame": 1.5, "t": 2}]), False, "frames.0.frame"
    ),
    Sample(C, "relay", json.dumps(FRAME_TIMES), False),
    Sample(C, "client", _with(DETECTIONS, locked=[1, 2, 30, 40]), True),
    Sample(C, "client", _with(DETECTIONS, locked=None), True),
    Sample(C, "client", _with(DETECTIONS, locked=[1, 2]), False, "locked"),
    Sample(C, "client", _with(DETECTIONS, candidates=[[1, 2, 30, 40], [50, 60, 7, 8]]), True),
    Sample(C, "client", _with(DETECTIONS, candidates=[]), True),
    Sample(C, "client", _with(DETECTIONS, candidates=[[1, 2, 30]]), False, "candidates"),
    Sample(C, "client", '{"type": "robotStopped", "by": "ann", "reason": "Stop robot"}', True),
    Sample(C, "client", '{"type": "robotStopped", "by": null, "reason": "nobody"}', True),
    Sample(C, "client", '{"type": "robotStopped", "by": "ann"}', False, "reason"),
    Sample(C, "client", '{"type": "robotStopped", "by": "", "reason": "r"}', False, "by"),
    Sample(C, "client", '{"type": "stopRobot"}', False),
    Sample(C, "client", '{"type": "lockState", "state": "locked", "box": [1, 2, 3, 4]}', True),
    Sample(C, "client", '{"type": "lockState", "state": "none", "reason": "lost"}', True),
    Sample(C, "client", '{"type": "lockState", "state": "held"}', False, "state"),
    Sample(C, "client", '{"type": "lockState", "box": null}', False, "state"),
    Sample(C, "client", '{"type": "unlock"}', False),
    Sample(C, "client", '{"type": "goal"}', False),
]
