"""BlazeFace decoding: anchors, scores, boxes and keypoints back to frame pixels, and NMS.

BlazeFace (MediaPipe's face detector, vendored as TFLite files in ``app/static/vendor``) answers
each forward pass with one score logit and 16 numbers per anchor: the box's centre offset and
size, then six keypoints (eyes, nose, mouth, ears), each relative to its anchor in input
pixels. This module turns those raw outputs into boxes on the frame: the anchors from the spec's
``anchors`` (SSD anchors of a fixed size: ``perCell`` of them at the centre of each cell of a
``stride`` grid), sigmoid scores kept from ``scoreThreshold``, each box mapped back through the
letterbox that fitted its part of the frame into the square input, and greedy NMS over every
pass. The passes (:func:`passes`) are the whole frame and tiles at the model's own scale, so
faces too small for the whole-frame pass are found in a tile.

Pure numpy, no OpenCV and no I/O: the twin of ``app/static/js/core/blazeface.js``, both checked
on the sequences of ``tests/vision/blazeface_sequences.py`` (``tests/vision/test_blazeface.py``,
``e2e/test_blazeface_js.py``). Rounding is written out (floor of x + 0.5) so both compute the
same integers from the same doubles.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Box = tuple[int, int, int, int]
Floats = npt.NDArray[np.float64]
# Numbers per anchor in the regressors output: box (dx, dy, w, h), then 6 keypoints (x, y).
COORDS = 16
KEYPOINTS = 6


@dataclass(frozen=True)
class AnchorLayer:
    """``per_cell`` anchors at the centre of each cell of a ``stride``-pixel grid."""

    stride: int
    per_cell: int


@dataclass(frozen=True)
class Letterbox:
    """A part ``(x, y, w, h)`` of the frame scaled by ``scale`` into the top-left corner of
    the square input (the rest is padding)."""

    region: Box
    scale: float
    # The scaled part's size in input pixels (what the resize writes).
    width: int
    height: int


@dataclass(frozen=True)
class Face:
    """One face: its box in frame pixels, its score (0..1) and its 6 keypoints (frame pixels)."""

    box: Box
    score: float
    keypoints: tuple[tuple[float, float], ...]


def anchors(input_size: int, layers: Sequence[AnchorLayer]) -> Floats:
    """Anchor centres ``(x, y)`` in input pixels, in the model's output order: layer by layer,
    row by row, cell by cell, ``per_cell`` times each."""
    centres: list[tuple[float, float]] = []
    for layer in layers:
        cells = math.ceil(input_size / layer.stride)
        for row in range(cells):
            for col in range(cells):
                centre = ((col + 0.5) * layer.stride, (row + 0.5) * layer.stride)
                centres.extend([centre] * layer.per_cell)
    return np.array(centres, dtype=np.float64)


def letterbox(region: Box, input_size: int) -> Letterbox:
    """How the part ``region`` of the frame fits the square input: scaled so its longer side
    fills it, its shorter side rounded (at least one pixel)."""
    _, _, w, h = region
    scale = input_size / max(w, h)
    return Letterbox(
        region=region,
        scale=scale,
        width=max(1, math.floor(w * scale + 0.5)),
        height=max(1, math.floor(h * scale + 0.5)),
    )


def passes(width: int, height: int, tile: float, overlap: float) -> list[Box]:
    """The parts of a ``width`` × ``height`` frame one detection searches: the whole frame,
    then square tiles ``tile`` of the frame's width wide (0: none), overlapping by ``overlap``
    of a tile, laid evenly from edge to edge (a frame no larger than a tile gets no tiles). A
    tile is a share of the frame, not a number of pixels, so a larger frame costs as many
    passes and finds the same faces relative to its size."""
    parts: list[Box] = [(0, 0, width, height)]
    wanted = math.floor(tile * width + 0.5)
    if wanted <= 0 or (width <= wanted and height <= wanted):
        return parts
    side = min(wanted, width, height)
    xs = _starts(width, side, overlap)
    ys = _starts(height, side, overlap)
    parts.extend((x, y, side, side) for y in ys for x in xs)
    return parts


def around(box: Box, margin: float, width: int, height: int) -> Box | None:
    """The square part of a ``width`` × ``height`` frame one forward pass searches between full
    scans: centred on the last target ``box``, ``margin`` of its longer side wider on each side,
    moved inside the frame (and cut to it where larger); None when empty."""
    x, y, w, h = box
    side = math.ceil(max(w, h) * (1.0 + 2.0 * margin))
    sw, sh = min(side, width), min(side, height)
    x0 = min(max(0, math.floor(x + w / 2 - sw / 2)), width - sw)
    y0 = min(max(0, math.floor(y + h / 2 - sh / 2)), height - sh)
    if sw <= 0 or sh <= 0:
        return None
    return x0, y0, sw, sh


def _starts(length: int, side: int, overlap: float) -> list[int]:
    """Tile origins along one axis: the fewest tiles of ``side`` whose neighbours overlap by at
    least ``overlap`` of a tile, spread evenly so the last ends at ``length``."""
    if length <= side:
        return [0]
    step = side * (1.0 - overlap)
    count = 1 + math.ceil((length - side) / step)
    return [math.floor(i * (length - side) / (count - 1) + 0.5) for i in range(count)]


def decode(
    scores: Sequence[float] | Floats,
    raw: Sequence[float] | Floats,
    centres: Floats,
    fit: Letterbox,
    threshold: float,
) -> list[Face]:
    """The faces of one forward pass: ``scores`` (one logit per anchor) and ``raw`` (``COORDS``
    per anchor, flat) decoded against ``centres`` (:func:`anchors`), kept where the sigmoid of
    the logit is at least ``threshold``, mapped back to frame pixels through ``fit``."""
    logits = np.asarray(scores, dtype=np.float64).reshape(-1)
    values = np.asarray(raw, dtype=np.float64).reshape(-1, COORDS)
    faces: list[Face] = []
    for i in range(len(centres)):
        score = sigmoid(float(logits[i]))
        if score < threshold:
            continue
        ax, ay = float(centres[i][0]), float(centres[i][1])
        row = [float(v) for v in values[i]]
        cx, cy, w, h = ax + row[0], ay + row[1], row[2], row[3]
        box = to_frame(fit, cx - w / 2, cy - h / 2, w, h)
        points = tuple(
            to_point(fit, ax + row[4 + 2 * k], ay + row[5 + 2 * k]) for k in range(KEYPOINTS)
        )
        faces.append(Face(box=box, score=score, keypoints=points))
    return faces


def sigmoid(logit: float) -> float:
    """The score of a logit, clipped to ±100 as MediaPipe clips it."""
    clipped = min(100.0, max(-100.0, logit))
    return 1.0 / (1.0 + math.exp(-clipped))


def to_point(fit: Letterbox, x: float, y: float) -> tuple[float, float]:
    """An input-pixel point back in frame pixels."""
    return fit.region[0] + x / fit.scale, fit.region[1] + y / fit.scale


def to_frame(fit: Letterbox, x: float, y: float, w: float, h: float) -> Box:
    """An input-pixel box back in frame pixels, rounded."""
    fx, fy = to_point(fit, x, y)
    return (
        math.floor(fx + 0.5),
        math.floor(fy + 0.5),
        math.floor(w / fit.scale + 0.5),
        math.floor(h / fit.scale + 0.5),
    )


def iou(a: Box, b: Box) -> float:
    """Intersection over union of two boxes (0 when either is empty)."""
    ix = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = a[2] * a[3] + b[2] * b[3] - inter
    return inter / union if union > 0 else 0.0


def suppress(faces: Sequence[Face], overlap: float, min_size: int) -> list[Face]:
    """Greedy NMS: faces at least ``min_size`` pixels tall, best score first (the earlier of
    equal scores), each dropped when it overlaps a kept one by more than ``overlap`` (IoU)."""
    order = sorted(
        (i for i, face in enumerate(faces) if face.box[3] >= min_size),
        key=lambda i: (-faces[i].score, i),
    )
    kept: list[Face] = []
    for i in order:
        if all(iou(faces[i].box, k.box) <= overlap for k in kept):
            kept.append(faces[i])
    return kept
