"""``autopilot bench --camera``: what the simulated robot's camera costs per frame.

Renders the arena as the robot sees it while the walker walks its round and the robot follows it
as a perfect follower would -- a metre and a half behind, facing it, so the walker's face is in
every frame and the other billboards come and go behind it -- frame by frame at the camera's
rate of arena time: the render and the JPEG encode timed apart, each frame's JPEG size kept. The
same frames of the empty arena (walls, floor and ceiling alone) are the baseline: what the
billboards add.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

from app.diffdrive.arena import ARENA, WALK, Arena
from app.diffdrive.camera import Pinhole, Renderer, encode_jpeg
from app.diffdrive.robot import DiffDrive, RobotState
from app.diffdrive.sim import Placed, Scene
from app.tools.bench.stats import summarize

QUICK_FRAMES, FULL_FRAMES = 300, 1800
# How far behind the walker the perfect follower keeps (m).
STANDOFF_M = 1.5


def _frames(arena: Arena, camera: Pinhole, frames: int) -> dict[str, Any]:
    """Render and encode ``frames`` frames of ``arena``; the timings' summaries (ms) and sizes."""
    renderer = Renderer(arena, camera)
    render_ms: list[float] = []
    encode_ms: list[float] = []
    sizes: list[float] = []
    for scene in _following(arena, camera.fps, frames):
        started = time.perf_counter()
        image = renderer.render(scene)
        rendered = time.perf_counter()
        data = encode_jpeg(image)
        encoded = time.perf_counter()
        render_ms.append((rendered - started) * 1000)
        encode_ms.append((encoded - rendered) * 1000)
        sizes.append(len(data))
    figures: dict[str, Any] = {}
    for key, values in (("render_ms", render_ms), ("encode_ms", encode_ms), ("jpeg_bytes", sizes)):
        summary = summarize(values)
        assert summary is not None  # frames > 0
        figures[key] = {k: round(v, 3) for k, v in summary.as_dict().items()}
    return figures


def _following(arena: Arena, fps: float, frames: int) -> Iterator[Scene]:
    """The arena frame by frame, seen by a robot on a leash: each frame it stands
    :data:`STANDOFF_M` from the walker on the line from where it stood, facing the walker
    (kept inside the walls)."""
    margin = DiffDrive.RADIUS_M
    rx, ry = arena.start.x, arena.start.y
    for frame in range(frames):
        t = frame / fps
        x, y = WALK.at(t)
        away = math.atan2(ry - y, rx - x)
        rx = min(max(x + STANDOFF_M * math.cos(away), margin), arena.width - margin)
        ry = min(max(y + STANDOFF_M * math.sin(away), margin), arena.depth - margin)
        robot = RobotState(rx, ry, math.atan2(y - ry, x - rx), 0.0, 0.0)
        placed = tuple(Placed(b, b.placed(t, (rx, ry))) for b in arena.billboards)
        yield Scene(t, robot, placed, round(t / DiffDrive.TICK_S))


def run(out: Path, frames: int, fps: float) -> dict[str, Any]:
    """Measure ``frames`` frames of the full arena and of the empty one; write camera.md and
    camera.json into ``out``."""
    camera = Pinhole(fps=fps)
    obj = {
        "frames": frames,
        "size": [camera.width, camera.height],
        "fps": fps,
        "arena": _frames(ARENA, camera, frames),
        "empty_arena": _frames(replace(ARENA, billboards=()), camera, frames),
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "camera.json").write_text(json.dumps(obj, indent=2) + "\n")
    (out / "camera.md").write_text(report(obj))
    return obj


def report(obj: dict[str, Any]) -> str:
    """The figures as a Markdown table."""
    width, height = obj["size"]
    lines = [
        "# The simulated camera's cost per frame",
        "",
        f"{obj['frames']} frames of {width}×{height} at {obj['fps']:g} fps of arena time, the"
        f" robot following the walker {STANDOFF_M:g} m behind it, rendered and JPEG-encoded"
        " (quality 80) one after the other on one core (`autopilot bench --camera`).",
        "",
        "| scene | render p50 / p95 (ms) | encode p50 / p95 (ms) | JPEG p50 (KB) |",
        "|---|---|---|---|",
    ]
    for key, label in (("arena", "the arena"), ("empty_arena", "empty arena (baseline)")):
        found = obj[key]
        render, encode = found["render_ms"], found["encode_ms"]
        lines.append(
            f"| {label} | {render['p50']:.2f} / {render['p95']:.2f} | "
            f"{encode['p50']:.2f} / {encode['p95']:.2f} | {found['jpeg_bytes']['p50'] / 1000:.1f} |"
        )
    return "\n".join(lines) + "\n"
