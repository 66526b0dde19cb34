"""The relay's analyzer (vision.js) as the relay page uses it, in headless Chromium."""

from __future__ import annotations

import base64
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest
from playwright.sync_api import Page

from app.protocol import frametag
from app.protocol.relay_profiles import PROFILES
from app.resources import OPERATIONS_SPEC
from app.vision.reference import detect
from app.vision.spec import load_spec
from tests.helpers.harness import analyzer_page

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SPEC = load_spec(OPERATIONS_SPEC)

# Helpers evaluated in the harness page (which has toBase64 and fromBase64): raw RGBA from
# Python, and a VideoFrame drawn on a canvas.
PAGE_HELPERS = """() => {
window.rawFrame = (width, height, b64) => (
  { width, height, data: new Uint8ClampedArray(fromBase64(b64).buffer) });
window.flameVideoFrame = (width, height, box) => {
  const canvas = new OffscreenCanvas(width, height);
  const ctx = canvas.getContext('2d');
  ctx.fillStyle = 'rgb(60, 90, 140)';
  ctx.fillRect(0, 0, width, height);
  ctx.fillStyle = 'rgb(255, 120, 0)';
  ctx.fillRect(...box);
  return new VideoFrame(canvas, { timestamp: 0 });
};
}"""


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with analyzer_page(PAGE_HELPERS) as opened:
        yield opened


def analyze_raw(page: Page, rgba: np.ndarray, op: str, **options: Any) -> Any:
    height, width = rgba.shape[:2]
    return page.evaluate(
        "([w, h, b64, op, options]) => window.analyzer.analyze(rawFrame(w, h, b64), op, options)",
        [width, height, base64.b64encode(rgba.tobytes()).decode(), op, options],
    )


def tagged_frame(number: int, width: int = 640, height: int = 480) -> np.ndarray:
    """A grey RGBA frame carrying ``number`` as the contract's frame tag."""
    frame = np.full((height, width, 4), 90, np.uint8)
    frame[..., 3] = 255
    frametag.stamp(frame[..., :3], number)
    return frame


def test_ops_and_default_come_from_the_spec(page: Page) -> None:
    ops = page.evaluate("window.analyzer.ops")
    assert [o["id"] for o in ops] == [o.id for o in SPEC.operations]
    assert all(o["label"] and o["description"] for o in ops)
    assert page.evaluate("window.analyzer.defaultOp") == SPEC.default


def test_unknown_op_is_rejected_by_name_and_the_analyzer_keeps_working(page: Page) -> None:
    message = page.evaluate(
        """() => window.analyzer.analyze(flameVideoFrame(320, 240, [0, 0, 10, 10]), 'dance')
                 .then(() => 'resolved', (error) => error.message)"""
    )
    assert "dance" in message
    result = page.evaluate(
        "() => window.analyzer.analyze(flameVideoFrame(320, 240, [200, 40, 80, 120]), 'fire')"
    )
    assert result["op"] == "fire" and len(result["boxes"]) == 1


def test_video_frame_source_matches_python_on_the_same_pixels(page: Page) -> None:
    result = page.evaluate(
        """async () => {
             const r = await window.analyzer.analyze(
               flameVideoFrame(640, 480, [420, 300, 120, 90]), 'fire', { returnPixels: true });
             return { ...r, rgba: await toBase64(r.rgba) };
           }"""
    )
    assert (result["w"], result["h"]) == (640, 480)
    x, y, w, h = result["boxes"][0]
    assert abs(x - 420) <= 3 and abs(y - 300) <= 3 and abs(w - 120) <= 6 and abs(h - 90) <= 6
    rgba = np.frombuffer(base64.b64decode(result["rgba"]), np.uint8).reshape(480, 640, 4)
    python = detect(SPEC.op("fire"), rgba)
    assert [list(b) for b in python.boxes] == result["boxes"]
    assert result["ms"] >= 0 and result["frame"] is None


def test_raw_rgba_source_and_frame_tag(page: Page) -> None:
    for number in (0, 1, 123_456, 2**24 - 1):
        result = analyze_raw(page, tagged_frame(number), "face")
        assert result["frame"] == number
    untagged = np.full((480, 640, 4), 255, np.uint8)
    assert analyze_raw(page, untagged, "face")["frame"] is None


def test_thesis_profile_runs_its_own_parameters(page: Page) -> None:
    # A small flame is kept by the full-resolution thesis profile and by the reduced default.
    frame = np.full((480, 1280, 4), 255, np.uint8)
    frame[..., :3] = (40, 40, 40)
    frame[200:260, 600:700, :3] = (255, 110, 0)
    for profile in PROFILES:
        result = analyze_raw(page, frame, "fire", profile=profile)
        expected = detect(SPEC.op("fire"), frame, profile)
        assert result["boxes"] == [list(b) for b in expected.boxes] != []


def test_wasm_heap_stays_flat_over_many_frames(page: Page) -> None:
    # The heap starts at 128 MB and only grows. Full-HD frames make a leak of any frame-sized
    # Mat (2 MB gray, 8 MB RGBA) outgrow it within the loop; a flat heap means none leaked.
    heap = page.evaluate(
        """async () => {
             const run = async (n) => {
               for (let i = 0; i < n; i += 1) {
                 // face_dnn's full scan is too slow for this loop in OpenCV.js; its Mats are
                 // the same few per pass, freed as the cascades' are.
                 for (const op of window.analyzer.ops.filter((o) => o.id !== 'face_dnn')) {
                   const frame = flameVideoFrame(1920, 1080, [i % 50, 20, 60, 40]);
                   await window.analyzer.analyze(frame, op.id);
                 }
               }
               return (await window.analyzer.memory()).wasmHeapBytes;
             };
             const warm = await run(3);
             return [warm, await run(40)];
           }"""
    )
    assert heap[1] == heap[0], heap


def test_wasm_heap_stays_flat_over_many_face_dnn_snapshots(page: Page) -> None:
    # What the relay runs between face_dnn's full scans: one BlazeFace pass in the window around
    # the target (`around`), on full-HD frames, after a full scan (13 passes) in the warm-up. A
    # frame-sized Mat leaked per snapshot (the RGB copy: 6 MB) outgrows the heap within the loop
    # (with one leaked on purpose it grew from 128 to 184 MiB).
    heap = page.evaluate(
        """async () => {
             const run = async (n, fullScanFirst) => {
               for (let i = 0; i < n; i += 1) {
                 const frame = flameVideoFrame(1920, 1080, [i % 50, 20, 60, 40]);
                 const full = fullScanFirst && i === 0;
                 const around = full ? null : [800 + (i % 9) * 20, 400, 240, 240];
                 const found = await window.analyzer.analyze(frame, 'face_dnn', { around });
                 if ((found.scan === 'window') !== (around !== null)) throw new Error(found.scan);
               }
               return (await window.analyzer.memory()).wasmHeapBytes;
             };
             const warm = await run(3, true);
             return [warm, await run(20, false)];
           }"""
    )
    assert heap[1] == heap[0], heap
