"""Camera test frames: a known picture with its number in it, as each camera message type.

:func:`pattern` draws four coloured quadrants and stamps ``number`` (the frame tag's blocks,
:mod:`app.protocol.frametag`) across the top of its lower half, where the agent's own tag (along
the top edge) does not reach. :func:`read_back` finds both in a frame the agent sent.
"""

from __future__ import annotations

import base64
import math
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from app.protocol import frametag
from vehicle_agent.rosimage import fit

Pixels = npt.NDArray[np.uint8]

# The quadrants' colours (RGB): top left, top right, bottom left, bottom right.
QUADRANTS = ((220, 40, 40), (40, 200, 60), (40, 60, 220), (230, 220, 40))
# Where each quadrant's colour is sampled, as fractions of the picture: its centre, below the
# agent's tag and clear of the picture's own.
_SAMPLES = ((0.25, 0.3), (0.75, 0.3), (0.25, 0.8), (0.75, 0.8))


def pattern(width: int, height: int, number: int) -> Pixels:
    """The test picture (RGB), ``number`` stamped into it."""
    rgb = np.empty((height, width, 3), np.uint8)
    half_w, half_h = width // 2, height // 2
    rgb[:half_h, :half_w] = QUADRANTS[0]
    rgb[:half_h, half_w:] = QUADRANTS[1]
    rgb[half_h:, :half_w] = QUADRANTS[2]
    rgb[half_h:, half_w:] = QUADRANTS[3]
    frametag.stamp(rgb[half_h:], number)
    return rgb


def colours(picture: Pixels) -> list[tuple[int, int, int]]:
    """The colour at each quadrant's sample point."""
    height, width = picture.shape[:2]
    return [
        tuple(int(v) for v in picture[int(fy * height), int(fx * width)])  # type: ignore[misc]
        for fx, fy in _SAMPLES
    ]


def pattern_error(picture: Pixels, grey: bool = False) -> int:
    """How far (0..255) the worst quadrant sample of ``picture`` is from its colour (``grey``:
    from its grey, as a mono8 camera sees it): 0 for the pattern itself, a few units after a
    JPEG's loss, ~100 or more for another picture."""
    expected = [tuple(c) for c in QUADRANTS]
    if grey:
        levels = cv2.cvtColor(np.array([QUADRANTS], np.uint8), cv2.COLOR_RGB2GRAY)[0]
        expected = [(int(v),) * 3 for v in levels]
    return max(
        abs(seen - want)
        for sample, colour in zip(colours(picture), expected, strict=True)
        for seen, want in zip(sample, colour, strict=True)
    )


def read_back(frame: Pixels, source: tuple[int, int]) -> tuple[int | None, Pixels]:
    """From a frame the agent sent: the number :func:`pattern` stamped, and the picture brought
    back to its ``source`` size (out of the letterbox)."""
    height, width = frame.shape[:2]
    placed = fit(*source, (width, height))
    x, y = placed.offset
    inner = frame[y : y + placed.scaled[1], x : x + placed.scaled[0]]
    picture = np.asarray(cv2.resize(inner, source, interpolation=cv2.INTER_AREA), np.uint8)
    return frametag.read(picture[source[1] // 2 :]), picture


def stamp(seconds: float) -> dict[str, int]:
    """A ROS 2 ``builtin_interfaces/Time``."""
    whole = math.floor(seconds)
    return {"sec": whole, "nanosec": min(999_999_999, round((seconds - whole) * 1e9))}


def compressed(
    rgb: Pixels, codec: str, seconds: float, format_: str | None = None, frame_id: str = "camera"
) -> dict[str, Any]:
    """A ``sensor_msgs/CompressedImage`` of ``rgb`` (``data`` as bytes)."""
    ok, encoded = cv2.imencode(f".{codec}", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    assert ok
    return {
        "header": {"stamp": stamp(seconds), "frame_id": frame_id},
        "format": format_ or codec,
        "data": encoded.tobytes(),
    }


def raw(rgb: Pixels, encoding: str, seconds: float, padding: int = 0) -> dict[str, Any]:
    """A ``sensor_msgs/Image`` of ``rgb`` in ``encoding`` (rgb8, bgr8, mono8), each row followed
    by ``padding`` bytes of 0xAB (``step`` counts them)."""
    if encoding == "rgb8":
        pixels = rgb
    elif encoding == "bgr8":
        pixels = cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)
    else:
        pixels = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)[:, :, None]
    height, width, channels = pixels.shape
    rows = np.full((height, width * channels + padding), 0xAB, np.uint8)
    rows[:, : width * channels] = pixels.reshape(height, width * channels)
    return {
        "header": {"stamp": stamp(seconds), "frame_id": "camera"},
        "height": height,
        "width": width,
        "encoding": encoding,
        "is_bigendian": 0,
        "step": width * channels + padding,
        "data": rows.tobytes(),
    }


def as_json(msg: dict[str, Any]) -> dict[str, Any]:
    """``msg`` as a JSON publisher sends it: ``data`` in base64."""
    return {**msg, "data": base64.b64encode(msg["data"]).decode("ascii")}
