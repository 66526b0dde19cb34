"""``autopilot bench --opencv-builds``: the tracking operations on each OpenCV.js build, side by
side.

One parity page per build (``?opencv=``) in one Chromium. Each frame of the agent's synthetic
scene is analysed by every operation that tracks (the cascades and the DNN face; ``--ops`` names
fewer) with the default profile on each build in turn (a full scan, then the window around the
largest box, as detect-then-track does between full scans) and by Python, so that the machine's
drift falls on every side alike; each is timed a few times and the fastest kept
(:mod:`app.tools.bench.jsnative`).

What decides is the relay's own work: it scans the frame in full once every ``full_scan_every``
snapshots and the window in between, and in full on every snapshot while it has nothing to
follow. Each frame's cost on each build is weighted so, and the figure is the median of the
per-frame ratios between the builds. :func:`verdict` says which build does an operation's work
better, or that they are level; :func:`choose` turns the verdicts into the build the relay should
load (one worker loads one build, for every operation it may be switched to);
``RELAY_OPENCV_BUILD`` (``app/protocol/opencv.py``) is the one it does load, and the bench fails
when the two differ.

The figures, the decision and the report's text are pure (:func:`op_figures`, :func:`choose`,
:func:`report_text`); :func:`compare_builds` is the browser side.
"""

from __future__ import annotations

import base64
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

import cv2
import numpy as np
from playwright.async_api import Browser, Page

from app.protocol.opencv import OPENCV_BUILDS, RELAY_OPENCV_BUILD, OpenCvBuild
from app.server.config import Settings
from app.tools.bench.jsnative import (
    ANALYZE_JS,
    LOAD_JS,
    REPEATS,
    WARMUP_FRAMES,
    Rgba,
    parity_page,
)
from app.tools.parity import IOU_THRESHOLD, SCORE_TOLERANCE, boxes_agree
from app.vision import window
from app.vision.reference import Detection, detect
from app.vision.spec import CascadeOperation, DnnOperation, load_spec

# The operations that detect, then track: a full scan now and then, a window in between.
Tracking = CascadeOperation | DnnOperation

PROFILE: Final = "default"
# A build does an operation's work better when it takes at most this share of the other's time
# (the median of the per-frame ratios): a self-built, patched file is a cost of its own, and a
# smaller gain is within what two runs of one build differ by on a shared machine.
SPEEDUP_RATIO: Final = 0.9
# ... and when it is faster on at least three frames in four (the per-frame ratios' upper
# quartile below 1, or for the official build their lower quartile above 1), so that a few lucky
# frames cannot carry the median.
FASTER_QUANTILE: Final = 75.0
SLOWER_QUANTILE: Final = 25.0

Verdict = Literal["simd", "official", "level"]


@dataclass
class FrameTimes:
    """One frame's detection times (ms, the fastest of the repeats) for one operation."""

    full_ms: dict[OpenCvBuild, float]
    # The window search around the largest box each build found; None where it found none.
    window_ms: dict[OpenCvBuild, float | None]
    python_ms: float
    # Whether each build's full-scan boxes were exactly Python's.
    agrees: dict[OpenCvBuild, bool]

    def relay_ms(self, build: OpenCvBuild, full_scan_every: int) -> float:
        """The time per snapshot the relay spends on this frame with ``build``: one full scan in
        ``full_scan_every`` and the window in between, or a full scan each time while it has
        nothing to follow."""
        windowed = self.window_ms[build]
        if windowed is None:
            return self.full_ms[build]
        return (self.full_ms[build] + (full_scan_every - 1) * windowed) / full_scan_every


@dataclass
class OpTimes:
    """Every counted frame of one tracking operation."""

    op: str
    full_scan_every: int
    frames: list[FrameTimes] = field(default_factory=list)


def _quantile(values: list[float], q: float, digits: int) -> float | None:
    return round(float(np.percentile(values, q)), digits) if values else None


def _compare(first: list[float], second: list[float]) -> dict[str, float | int | None]:
    """The median and quartiles of the per-frame ratios."""
    ratios = [a / b for a, b in zip(first, second, strict=True) if b > 0]
    return {
        "frames": len(ratios),
        "ratio": _quantile(ratios, 50.0, 3),
        "ratio_q1": _quantile(ratios, SLOWER_QUANTILE, 3),
        "ratio_q3": _quantile(ratios, FASTER_QUANTILE, 3),
    }


def op_figures(times: OpTimes) -> dict[str, Any]:
    """One operation's figures: per scan (full, window, relay) each build's p50 ms and the
    ratios SIMD / official frame by frame; Python's full-scan p50; how often each build's boxes
    were Python's."""
    simd, official = OPENCV_BUILDS
    frames = times.frames
    both = [
        f for f in frames if f.window_ms[simd] is not None and f.window_ms[official] is not None
    ]
    series: dict[str, dict[OpenCvBuild, list[float]]] = {
        "full": {b: [f.full_ms[b] for f in frames] for b in OPENCV_BUILDS},
        "window": {b: [f.window_ms[b] or 0.0 for f in both] for b in OPENCV_BUILDS},
        "relay": {b: [f.relay_ms(b, times.full_scan_every) for f in frames] for b in OPENCV_BUILDS},
    }
    out: dict[str, Any] = {
        "op": times.op,
        "frames": len(frames),
        "full_scan_every": times.full_scan_every,
        "agrees": {b: sum(f.agrees[b] for f in frames) for b in OPENCV_BUILDS},
    }
    for scan, by_build in series.items():
        out[scan] = {b: _quantile(by_build[b], 50.0, 2) for b in OPENCV_BUILDS}
        out[scan] |= _compare(by_build[simd], by_build[official])
    out["full"]["python"] = _quantile([f.python_ms for f in frames], 50.0, 2)
    return out


def verdict(op: dict[str, Any]) -> tuple[Verdict, str]:
    """Which build does one operation's relay work better (:func:`op_figures`), and why: SIMD
    when it agreed with Python wherever the official build did and took at most
    ``SPEEDUP_RATIO`` of the time (median per-frame ratio) while faster on three frames in four;
    the official build when SIMD agreed less often, or took at least 1 / ``SPEEDUP_RATIO`` of its
    time while slower on three frames in four; else level."""
    simd, official = OPENCV_BUILDS
    if op["agrees"][simd] < op["agrees"][official]:
        return official, (
            f"{op['op']}: the SIMD build's boxes were Python's on {op['agrees'][simd]} of"
            f" {op['frames']} frames, the official build's on {op['agrees'][official]}"
        )
    ratio, q1, q3 = (op["relay"].get(key) for key in ("ratio", "ratio_q1", "ratio_q3"))
    shown = f"{op['op']} {ratio} (p25 {q1}, p75 {q3})"
    if ratio is None or q1 is None or q3 is None:
        return "level", f"{op['op']}: not timed"
    if ratio <= SPEEDUP_RATIO and q3 < 1.0:
        return simd, shown
    if ratio >= 1 / SPEEDUP_RATIO and q1 > 1.0:
        return official, shown
    return "level", shown


def choose(ops: list[dict[str, Any]]) -> tuple[OpenCvBuild, str]:
    """The build the relay should load, from :func:`op_figures` of the operations measured, and
    why. One worker loads one build, and the client may switch it to any operation: SIMD when it
    does some operation's work better (:func:`verdict`) and none worse; else the official build,
    from npm as published, without a patch of ours."""
    simd, official = OPENCV_BUILDS
    if not ops:
        return official, "nothing was measured"
    found = [verdict(op) for op in ops]
    worse = [why for better, why in found if better == official]
    if worse:
        return official, "SIMD does worse on " + "; ".join(worse)
    faster = [why for better, why in found if better == simd]
    level = [why for better, why in found if better == "level"]
    if not faster:
        return official, (
            f"no speed-up of the relay's work: SIMD / official {', '.join(level)}, per frame;"
            f" SIMD needs a median ≤ {SPEEDUP_RATIO:g} and a p75 < 1 on some operation"
        )
    return simd, (
        f"SIMD / official per frame, faster on {', '.join(faster)}"
        + (f"; level on {', '.join(level)}" if level else "")
        + "; no operation slower and every one as often right"
    )


def report_text(found: dict[str, Any]) -> str:
    """``opencv-builds.md``: ``found`` holds the run's description, ``ops`` (each
    :func:`op_figures`), ``choice`` and ``reason`` (:func:`choose`) and ``relay_loads``."""
    simd, official = OPENCV_BUILDS
    lines = [
        "# The tracking operations on each OpenCV.js build",
        "",
        f"`{found['command']}` ({found['started']}; {found['machine']}; Chromium"
        f" {found['chromium']}; load average {found['load_average'][0]} before,"
        f" {found['load_average'][1]} after). {found['frames']} frames of the agent's synthetic"
        f" scene ({WARMUP_FRAMES} more first, not counted), 640×480, the {PROFILE} profile's"
        f" parameters; on each frame every build and Python in turn, the fastest of"
        f" {found['repeats']} run(s) each. Detection ms, p50 over the frames; the ratios are per"
        " frame, SIMD / official: their median and upper quartile. *relay* is the time per"
        " snapshot as the relay spends it: one full scan in `full_scan_every` and the window"
        " search in between,"
        " a full scan each time while nothing is found.",
        "",
        f"| operation | scan | frames | {simd} | {official} | ratio p50 | ratio p75 | Python |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for op in found["ops"]:
        for scan in ("full", "window", "relay"):
            row = {k: "–" if v is None else v for k, v in op[scan].items()}
            lines.append(
                f"| {op['op']} | {scan} | {row['frames']} | {row[simd]} | {row[official]}"
                f" | {row['ratio']} | {row['ratio_q3']} | {row.get('python', '')} |"
            )
    agreement = ", ".join(
        f"{op['op']} {op['agrees'][simd]} / {op['agrees'][official]} of {op['frames']}"
        for op in found["ops"]
    )
    lines += [
        "",
        f"Frames whose full-scan boxes were Python's ({simd} / {official}; the DNN's at IoU ≥"
        f" {IOU_THRESHOLD:g} with scores within {SCORE_TOLERANCE:g}, the others' exactly):"
        f" {agreement}.",
        "",
        "The better build per operation (median ≤ "
        f"{SPEEDUP_RATIO:g} and faster on three frames in four): "
        + ", ".join(f"{op['op']} {verdict(op)[0]}" for op in found["ops"])
        + ".",
        "",
        f"**Measured choice: {found['choice']}** — {found['reason']}.",
        "",
    ]
    if found["choice"] == found["relay_loads"]:
        lines.append(f"The relay loads the {found['relay_loads']} build (app/protocol/opencv.py).")
    else:
        lines.append(
            f"**The relay loads the {found['relay_loads']} build (app/protocol/opencv.py), not"
            " the one measured here.**"
        )
    return "\n".join(lines) + "\n"


def write_report(out: Path, found: dict[str, Any]) -> Path:
    """``opencv-builds.md`` and ``opencv-builds.json`` in ``out``; returns the report's path."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "opencv-builds.json").write_text(json.dumps(found, indent=2) + "\n")
    path = out / "opencv-builds.md"
    path.write_text(report_text(found))
    return path


def decide(found: dict[str, Any]) -> dict[str, Any]:
    """``found`` with the measured ``choice``, its ``reason`` and the build the relay loads."""
    choice, reason = choose(found["ops"])
    return found | {"choice": choice, "reason": reason, "relay_loads": RELAY_OPENCV_BUILD}


def tracking_ops(settings: Settings | None = None) -> list[str]:
    """The operations that detect, then track (the cascades and the DNN), in spec order: those
    the bench measures unless told fewer."""
    spec = load_spec((settings or Settings()).operations_spec)
    return [op.id for op in spec.operations if isinstance(op, Tracking)]


async def compare_builds(
    browser: Browser,
    base_url: str,
    frames: list[Rgba],
    settings: Settings | None = None,
    warmup: int = WARMUP_FRAMES,
    ops: list[str] | None = None,
    repeats: int = REPEATS,
) -> list[OpTimes]:
    """The tracking operations ``ops`` (by default :func:`tracking_ops`) on every build and in
    Python, frame by frame (module docstring), each timed ``repeats`` times and the fastest
    kept; the first ``warmup`` frames are not counted."""
    spec = load_spec((settings or Settings()).operations_spec)
    measured: list[Tracking] = []
    for op_id in ops or tracking_ops(settings):
        op = spec.op(op_id)
        if not isinstance(op, Tracking):
            raise ValueError(f"{op_id!r} does not track: it has no window to time")
        measured.append(op)
    found = [OpTimes(op.id, op.params_for(PROFILE).full_scan_every) for op in measured]
    pages: dict[OpenCvBuild, Page] = {}
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        for build in OPENCV_BUILDS:
            pages[build] = await parity_page(browser, base_url, build)
            if await pages[build].evaluate("document.body.dataset.opencv") != build:
                raise RuntimeError(f"the parity page did not load the {build} OpenCV.js")
        for i, rgba in enumerate(frames):
            encoded = base64.b64encode(rgba.tobytes()).decode("ascii")
            for page in pages.values():
                await page.evaluate(LOAD_JS, encoded)
            for op, times in zip(measured, found, strict=True):
                frame = await _time_frame(pages, op, rgba, repeats)
                if i >= warmup:
                    times.frames.append(frame)
        return found
    finally:
        cv2.setNumThreads(threads)
        for page in pages.values():
            await page.close()


async def _time_frame(
    pages: dict[OpenCvBuild, Page], op: Tracking, rgba: Rgba, repeats: int
) -> FrameTimes:
    height, width = rgba.shape[:2]
    full: dict[OpenCvBuild, list[float]] = {b: [] for b in pages}
    windowed: dict[OpenCvBuild, list[float]] = {b: [] for b in pages}
    boxes: dict[OpenCvBuild, list[window.Box]] = {}
    scores: dict[OpenCvBuild, list[float]] = {}
    python_ms: list[float] = []
    for _ in range(repeats):
        for build, page in pages.items():
            args: list[Any] = [width, height, op.id, PROFILE, None]
            js = await page.evaluate(ANALYZE_JS, args)
            full[build].append(float(js["ms"]))
            boxes[build] = [(x, y, w, h) for x, y, w, h in js["boxes"]]
            scores[build] = [float(score) for score in js["scores"]]
            around = window.largest(boxes[build])
            if around is not None:
                js = await page.evaluate(ANALYZE_JS, [*args[:-1], around])
                windowed[build].append(float(js["ms"]))
        started = time.perf_counter()
        native = detect(op, rgba, PROFILE)
        python_ms.append((time.perf_counter() - started) * 1000.0)
    return FrameTimes(
        full_ms={b: min(t) for b, t in full.items()},
        window_ms={b: min(t) if t else None for b, t in windowed.items()},
        python_ms=min(python_ms),
        agrees={b: agrees_with_python(boxes[b], scores[b], native) for b in pages},
    )


def agrees_with_python(boxes: list[window.Box], scores: list[float], native: Detection) -> bool:
    """A build's full scan against Python's: a scored operation's (the DNN's) as parity judges
    it, a cascade's box for box."""
    if native.scores:
        return boxes_agree(boxes, native.boxes, scores, native.scores)
    return sorted(boxes) == sorted(native.boxes)
