"""The analyzer on the kind of frame the relay hands it live: a decoded I420 VideoFrame.

The relay transfers each frame as a ``VideoFrame`` and the worker converts it to RGBA straight
into the reused frame Mat (``VideoFrame.copyTo``). These tests build such frames from known
pixels and check what a user of the relay relies on: the box lands where the flame is, Python
OpenCV on the analysed pixels finds the same box, frames sent back to back are each analysed
on their own pixels, and each frame's tag reads back.
"""

from __future__ import annotations

import base64
from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import pytest
from playwright.sync_api import Page

from app.protocol import frametag
from app.resources import OPERATIONS_SPEC
from app.vision import window
from app.vision.reference import detect
from app.vision.spec import load_spec
from tests.helpers.harness import analyzer_page
from tests.vision.frames import FACES

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SPEC = load_spec(OPERATIONS_SPEC)
WIDTH, HEIGHT = 640, 480
BACKGROUND_BGR = (140, 90, 60)
FLAME_BGR = (0, 120, 255)

# An I420 VideoFrame from base64 planes (Y, then U, then V): by default full-range BT.601 as
# OpenCV's BGR2YUV_I420 writes them, with sRGB primaries and transfer so that converting it to
# sRGB is the YUV matrix alone; the analyzer run on several such frames at once, or one call
# after another with options of their own (the harness page has toBase64 and fromBase64).
PAGE_HELPERS = """() => {
window.i420Frame = (width, height, b64, colorSpace = {
  primaries: 'bt709', transfer: 'iec61966-2-1', matrix: 'smpte170m', fullRange: true,
}) => new VideoFrame(fromBase64(b64), {
  format: 'I420', codedWidth: width, codedHeight: height, timestamp: 0, colorSpace,
});
const encoded = async (r) => (r.rgba ? { ...r, rgba: await toBase64(r.rgba) } : r);
window.analyzeAll = async (frames, op, options) => {
  const results = await Promise.all(
    frames.map(([w, h, b64]) => window.analyzer.analyze(i420Frame(w, h, b64), op, options)));
  return Promise.all(results.map(encoded));
};
window.analyzeInTurn = async (calls, colorSpace) => {
  const results = [];
  for (const [[w, h, b64], op, options] of calls) {
    const frame = i420Frame(w, h, b64, colorSpace);
    results.push(await encoded(await window.analyzer.analyze(frame, op, options)));
  }
  return results;
};
}"""


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with analyzer_page(PAGE_HELPERS) as opened:
        yield opened


def flame_scene(box: tuple[int, int, int, int]) -> npt.NDArray[np.uint8]:
    """A BGR frame: a flat background with one flame-coloured rectangle at ``box``."""
    frame = np.empty((HEIGHT, WIDTH, 3), np.uint8)
    frame[:] = BACKGROUND_BGR
    x, y, w, h = box
    frame[y : y + h, x : x + w] = FLAME_BGR
    return frame


def i420(bgr: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """The frame's I420 planes, as OpenCV encodes them."""
    return np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2YUV_I420), np.uint8)


def i420_payload(bgr: npt.NDArray[np.uint8]) -> list[Any]:
    """[width, height, base64 of the I420 planes] for the page's i420Frame helper."""
    return [bgr.shape[1], bgr.shape[0], base64.b64encode(i420(bgr).tobytes()).decode()]


def analyzed_rgba(result: dict[str, Any]) -> npt.NDArray[np.uint8]:
    rgba = np.frombuffer(base64.b64decode(result["rgba"]), np.uint8)
    return rgba.reshape(result["h"], result["w"], 4)


def close_to(found: list[int], drawn: tuple[int, int, int, int], slack: int = 4) -> bool:
    return all(abs(a - b) <= slack for a, b in zip(found, drawn, strict=True))


def test_i420_frame_is_converted_and_agrees_with_python(page: Page) -> None:
    drawn = (420, 300, 120, 90)
    scene = flame_scene(drawn)
    [result] = page.evaluate(
        "([frames, op]) => analyzeAll(frames, op, { returnPixels: true })",
        [[i420_payload(scene)], "fire"],
    )
    assert (result["w"], result["h"]) == (WIDTH, HEIGHT)
    assert len(result["boxes"]) == 1 and close_to(result["boxes"][0], drawn), result["boxes"]
    rgba = analyzed_rgba(result)
    # The conversion gave the picture OpenCV decodes from the same planes: not garbled, shifted,
    # rescaled or with red and blue swapped (255 levels on this orange). Chromium's YUV matrix
    # differs from OpenCV's by up to ~20 levels on saturated colours, hence the tolerance.
    decoded = cv2.cvtColor(i420(scene), cv2.COLOR_YUV2RGB_I420).astype(int)
    assert np.abs(rgba[..., :3].astype(int) - decoded).max() <= 24
    python = detect(SPEC.op("fire"), rgba)
    assert [list(b) for b in python.boxes] == result["boxes"]


def test_frames_sent_back_to_back_are_each_analysed_on_their_own_pixels(page: Page) -> None:
    # The relay keeps one analysis in flight, but the analyzer must not mix frames up when a
    # caller does not: they share one frame Mat in the worker.
    drawn = [(40 + 90 * i, 60 + 40 * i, 80, 70) for i in range(5)]
    results = page.evaluate(
        "([frames, op]) => analyzeAll(frames, op, {})",
        [[i420_payload(flame_scene(box)) for box in drawn], "fire"],
    )
    found = [r["boxes"] for r in results]
    assert all(
        len(boxes) == 1 and close_to(boxes[0], box) for boxes, box in zip(found, drawn, strict=True)
    ), (found, drawn)


# A decoded video's frames as Chromium's VP8 decoder tags them: BT.601, limited range. The worker
# copies their planes as they are and converts, with OpenCV, only what an operation reads.
BT601_LIMITED = {
    "primaries": "smpte170m",
    "transfer": "smpte170m",
    "matrix": "smpte170m",
    "fullRange": False,
}
IN_TURN = "([calls, colorSpace]) => analyzeInTurn(calls, colorSpace)"

FACE_PHOTO = FACES / "obama-480p.jpg"


def face_scene() -> npt.NDArray[np.uint8]:
    """A 640×480 BGR photo of one face."""
    photo = cv2.imread(str(FACE_PHOTO))
    assert photo is not None, FACE_PHOTO
    return np.asarray(cv2.resize(photo, (WIDTH, HEIGHT), interpolation=cv2.INTER_AREA), np.uint8)


def as_rgba_by_python(bgr: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """What Python OpenCV makes of the frame's I420 planes."""
    return np.asarray(cv2.cvtColor(i420(bgr), cv2.COLOR_YUV2RGBA_I420), np.uint8)


def test_a_bt601_frame_converts_in_opencv_as_python_opencv_does(page: Page) -> None:
    scene = face_scene()
    call = [i420_payload(scene), "face", {"returnPixels": True}]
    [result] = page.evaluate(IN_TURN, [[call], BT601_LIMITED])
    assert np.array_equal(analyzed_rgba(result), as_rgba_by_python(scene))
    assert result["converted"] >= WIDTH * HEIGHT
    python = detect(SPEC.op("face"), as_rgba_by_python(scene))
    assert len(python.boxes) == 1 and [list(b) for b in python.boxes] == result["boxes"]


def test_a_window_search_converts_only_its_part_and_finds_what_python_finds(page: Page) -> None:
    # The frame Mat first holds noise, converted whole; the face frame's window search must
    # then see the face frame wherever it reads, though it converts only a part of it.
    scene = face_scene()
    rgba = as_rgba_by_python(scene)
    (face,) = detect(SPEC.op("face"), rgba).boxes
    noise = np.random.default_rng(3).integers(0, 256, scene.shape, np.uint8)
    noise_call = [i420_payload(noise), "face", {}]
    window_call = [i420_payload(scene), "face", {"around": list(face), "returnPixels": True}]
    _, windowed = page.evaluate(IN_TURN, [[noise_call, window_call], BT601_LIMITED])
    python = detect(SPEC.op("face"), rgba, around=face)
    assert python.boxes and [list(b) for b in python.boxes] == windowed["boxes"]
    assert python.region is not None and windowed["region"] == list(python.region)
    # Every pixel the window search reads is the face frame's; less than half the frame was
    # converted, and the rest still holds the noise.
    detect_width = SPEC.op("face").params.detect_width
    assert detect_width is not None
    size = (detect_width, HEIGHT * detect_width // WIDTH)
    rects = window.source_rect(python.region, WIDTH, HEIGHT, size)
    assert rects is not None
    read = window.crop(rgba, rects[1])
    analysed = analyzed_rgba(windowed)
    assert np.array_equal(window.crop(analysed, rects[1]), read)
    assert 0 < windowed["converted"] < WIDTH * HEIGHT / 2, windowed["converted"]
    assert not np.array_equal(analysed, rgba)


def lowered(bgr: npt.NDArray[np.uint8], rows: int) -> npt.NDArray[np.uint8]:
    """``bgr`` moved down by ``rows``, a flat band above it."""
    out = np.full_like(bgr, 110)
    out[rows:] = bgr[:-rows]
    return out


def test_the_tag_of_a_bt601_frame_reads_back_when_only_a_window_is_converted(page: Page) -> None:
    # The frame before carries another number, converted whole: a tag read from rows this frame
    # did not convert would read that number (or no tag) instead of this frame's.
    scene = lowered(face_scene(), 150)
    (face,) = detect(SPEC.op("face"), as_rgba_by_python(scene)).boxes
    before, tagged = scene.copy(), scene.copy()
    frametag.stamp(before, 0x123456)
    frametag.stamp(tagged, 0xABCDEF)
    # The window search reads nothing of the tag's rows (the 16 top rows of a 640-wide frame):
    # they are converted for the tag alone.
    detect_width = SPEC.op("face").params.detect_width
    assert detect_width is not None
    region = detect(SPEC.op("face"), as_rgba_by_python(tagged), around=face).region
    assert region is not None
    rects = window.source_rect(
        region, WIDTH, HEIGHT, (detect_width, HEIGHT * detect_width // WIDTH)
    )
    assert rects is not None and rects[1][1] >= 16, rects
    calls = [
        [i420_payload(before), "face", {}],
        [i420_payload(tagged), "face", {"around": list(face)}],
    ]
    first, windowed = page.evaluate(IN_TURN, [calls, BT601_LIMITED])
    assert first["frame"] == 0x123456
    assert 0 < windowed["converted"] < WIDTH * HEIGHT / 2, windowed["converted"]
    assert windowed["frame"] == 0xABCDEF


def test_the_tag_of_a_wide_bt601_frame_reads_back_when_only_a_window_is_converted(
    page: Page,
) -> None:
    # A frame wider than 4:3: its tag's blocks (16 rows high, from its width) reach below a
    # fortieth of its height, and a window far below them converts none of their rows. The
    # frame before holds the opposite bits, so any row left unconverted reads as its.
    width, height = 640, 240
    scene = np.asarray(cv2.resize(face_scene(), (width, height)), np.uint8)
    before, tagged = scene.copy(), scene.copy()
    frametag.stamp(before, 0x5A3C0F)
    frametag.stamp(tagged, 0x5A3C0F ^ 0xFFFFFF)
    calls = [
        [i420_payload(before), "face", {}],
        [i420_payload(tagged), "face", {"around": [280, 140, 80, 80]}],
    ]
    first, windowed = page.evaluate(IN_TURN, [calls, BT601_LIMITED])
    assert first["frame"] == 0x5A3C0F
    assert 0 < windowed["converted"] < width * height / 2, windowed["converted"]
    assert windowed["frame"] == 0x5A3C0F ^ 0xFFFFFF


def test_the_tag_of_a_full_range_i420_frame_reads_back(page: Page) -> None:
    # Chromium converts such a frame whole: its tag reads back from every block.
    frames = [flame_scene((40 + 90 * i, 200, 80, 70)) for i in range(3)]
    for i, frame in enumerate(frames):
        frametag.stamp(frame, 777 + i)
    results = page.evaluate(
        "([frames, op]) => analyzeAll(frames, op, {})", [[i420_payload(f) for f in frames], "fire"]
    )
    assert [r["frame"] for r in results] == [777, 778, 779]
