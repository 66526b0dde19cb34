"""OpenCV.js against Python OpenCV: the same frames, the same operation parameters, one thread each.

The JS side is the relay's own analyzer (Web Worker) on the parity page; its ``ms`` covers the
operation's ``detect`` on a ready RGBA Mat. The Python side times ``app.vision.spec.detect`` on the
same RGBA array with ``cv2.setNumThreads(1)``. Both pipelines start from RGBA (grey conversion,
reduction and detection included) so the ratio compares like with like. The two run one after
the other, never at the same time, so neither steals the other's core; each frame is timed a few
times on each side and the fastest run kept.
"""

from __future__ import annotations

import base64
import logging
import time
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
from playwright.async_api import Browser, Page

from app.protocol.opencv import OpenCvBuild
from app.protocol.relay_profiles import PROFILES, Profile
from app.server.config import Settings
from app.tools.parity import READY_TIMEOUT_MS
from app.vision import window
from app.vision.reference import detect
from app.vision.spec import CascadeParams, load_spec

log = logging.getLogger(__name__)

Rgba = npt.NDArray[np.uint8]

# First calls on either side pay for JIT tier-up, cascade caches and allocation: not counted.
WARMUP_FRAMES = 3
# Each frame is timed this many times on each side and the fastest kept: on a machine shared with
# other work, the minimum is the estimate least disturbed by what else runs (as timeit does).
REPEATS = 3

# Defined in the parity page: each frame's RGBA crosses to the page once, decoded there by the
# page's fromBase64, and every timed run analyses that copy (the analyzer copies the pixels to
# its worker, so the page's frame stays whole). around: search only the window around that box,
# as detect-then-track does between full scans.
LOAD_JS = "(b64) => { window.benchFrame = new Uint8ClampedArray(window.fromBase64(b64).buffer); }"
ANALYZE_JS = """async ([width, height, opId, profile, around]) => {
  const data = window.benchFrame;
  const r = await window.analyzer.analyze({ width, height, data }, opId, { profile, around });
  return { ms: r.ms, boxes: r.boxes, scores: r.scores ?? [] };
}"""


@dataclass
class Comparison:
    """Per-frame detection times on both sides and how often their boxes agreed."""

    profile: str
    js_ms: list[float] = field(default_factory=list)
    native_ms: list[float] = field(default_factory=list)
    # OpenCV.js searching only the window around the face it found (tracking profiles only).
    js_window_ms: list[float] = field(default_factory=list)
    same_boxes: int = 0
    frames: int = 0


def synthetic_frames(count: int) -> list[Rgba]:
    """``count`` frames of the agent's synthetic scene spread over one cycle of the face's path."""
    from vehicle_agent.video import SweepPath, SyntheticVideo

    fps = 15.0
    path = SweepPath()
    cycle_frames = int(path.cycle_s * fps)
    video = SyntheticVideo(fps=fps, path=path)
    frames = []
    for i in range(count):
        rgb = video.render(i * cycle_frames // count)
        frames.append(np.asarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2RGBA), dtype=np.uint8))
    return frames


async def compare(
    browser: Browser,
    base_url: str,
    frames: list[Rgba],
    profiles: tuple[Profile, ...] = PROFILES,
    op_id: str = "face",
    settings: Settings | None = None,
) -> dict[str, Comparison]:
    """Time ``op_id`` on every frame in OpenCV.js (in ``browser``) and in Python, per profile."""
    spec = load_spec((settings or Settings()).operations_spec)
    op = spec.op(op_id)
    page = await parity_page(browser, base_url)
    try:
        results: dict[str, Comparison] = {}
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)
        try:
            for profile in profiles:
                comparison = Comparison(profile)
                params = op.params_for(profile)
                tracks = isinstance(params, CascadeParams) and params.full_scan_every > 1
                for i, rgba in enumerate(frames):
                    height, width = rgba.shape[:2]
                    await page.evaluate(LOAD_JS, base64.b64encode(rgba.tobytes()).decode("ascii"))
                    js_ms, native_ms, window_ms = [], [], []
                    for _ in range(REPEATS):
                        js: dict[str, Any] = await page.evaluate(
                            ANALYZE_JS, [width, height, op_id, profile, None]
                        )
                        js_ms.append(float(js["ms"]))
                        started = time.perf_counter()
                        native = detect(op, rgba, profile)
                        native_ms.append((time.perf_counter() - started) * 1000.0)
                        around = window.largest([tuple(b) for b in js["boxes"]])
                        if around is not None and tracks:
                            windowed: dict[str, Any] = await page.evaluate(
                                ANALYZE_JS, [width, height, op_id, profile, around]
                            )
                            window_ms.append(float(windowed["ms"]))
                    if i < WARMUP_FRAMES:
                        continue
                    comparison.frames += 1
                    comparison.js_ms.append(min(js_ms))
                    comparison.native_ms.append(min(native_ms))
                    if window_ms:
                        comparison.js_window_ms.append(min(window_ms))
                    js_boxes = sorted(tuple(int(v) for v in box) for box in js["boxes"])
                    if js_boxes == sorted(native.boxes):
                        comparison.same_boxes += 1
                log.info(
                    "%s profile: OpenCV.js %.1f ms, Python %.1f ms (median of %d frames)%s",
                    profile,
                    float(np.median(comparison.js_ms)),
                    float(np.median(comparison.native_ms)),
                    comparison.frames,
                    f"; in the tracking window {np.median(comparison.js_window_ms):.1f} ms"
                    if comparison.js_window_ms
                    else "",
                )
                results[profile] = comparison
        finally:
            cv2.setNumThreads(threads)
        return results
    finally:
        await page.close()


async def parity_page(browser: Browser, base_url: str, build: OpenCvBuild | None = None) -> Page:
    """A parity page whose analyzer is ready, with OpenCV.js ``build`` (None: the relay's)."""
    page = await browser.new_page()
    await page.goto(f"{base_url}/parity" + ("" if build is None else f"?opencv={build}"))
    # A function, not an expression, which the page's CSP would refuse to eval.
    await page.wait_for_function(
        "() => document.body.dataset.ready !== undefined", timeout=READY_TIMEOUT_MS
    )
    if await page.evaluate("document.body.dataset.ready") != "true":
        state = await page.text_content("#state")
        await page.close()
        raise RuntimeError(f"the parity page's analyzer did not start: {state}")
    return page
