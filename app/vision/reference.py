"""The Python reference pipeline: the same OpenCV calls as ``app/static/js/worker/operations/``.

Parity checks run it on the exact pixels the relay's worker saw and compare the boxes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt
from cv2.typing import MatLike

from app.protocol.relay_profiles import PROFILES, Profile
from app.vision import blazeface, window
from app.vision.lock import look_rect
from app.vision.spec import (
    CASCADE_DIR,
    MODEL_DIR,
    AnyOperation,
    CascadeOperation,
    CascadeParams,
    ColourParams,
    DnnOperation,
    DnnParams,
    SpecError,
)

Rgba = npt.NDArray[np.uint8]
Box = tuple[int, int, int, int]


@dataclass(frozen=True)
class Detection:
    """Boxes ``(x, y, w, h)`` in full-frame pixels, sorted; the target point or None."""

    boxes: list[Box]
    target: tuple[float, float] | None
    # The window searched, in detection-image pixels; None for a full-frame scan.
    region: Box | None = None
    # Each box's score (0..1), in the boxes' order, for operations that score them (DNN).
    scores: tuple[float, ...] = ()


def _reduction(width: int, height: int, detect_width: int | None) -> tuple[int, int] | None:
    """Size of the detection image, or None when the frame is used as it is.

    Rounding is written out (floor of x + 0.5) because JavaScript's Math.round and Python's
    round() differ on halves; both sides compute the same doubles.
    """
    if detect_width is None or width <= detect_width:
        return None
    return detect_width, math.floor(height * detect_width / width + 0.5)


def _factor(width: int, size: tuple[int, int] | None) -> float:
    """What scales detection-image coordinates back to a frame ``width`` wide."""
    return 1.0 if size is None else width / size[0]


def _reduce(image: MatLike, detect_width: int | None) -> tuple[MatLike, float]:
    """The detection image (reduced with INTER_AREA when wider than ``detect_width``) and the
    factor that scales its coordinates back to the full frame."""
    height, width = image.shape[:2]
    size = _reduction(width, height, detect_width)
    if size is None:
        return image, 1.0
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA), _factor(width, size)


def _scale_box(box: Box, factor: float) -> Box:
    x, y, w, h = box
    return (
        math.floor(x * factor + 0.5),
        math.floor(y * factor + 0.5),
        math.floor(w * factor + 0.5),
        math.floor(h * factor + 0.5),
    )


def _centre_of_largest(boxes: list[Box]) -> tuple[float, float] | None:
    if not boxes:
        return None
    # max() keeps the first of equal areas, as the JS loop with a strict '>' does.
    x, y, w, h = max(boxes, key=lambda b: b[2] * b[3])
    return x + w / 2, y + h / 2


_classifiers: dict[str, cv2.CascadeClassifier] = {}


def _classifier(name: str) -> cv2.CascadeClassifier:
    if name not in _classifiers:
        classifier = cv2.CascadeClassifier(str(CASCADE_DIR / name))
        if classifier.empty():
            raise SpecError(f"cascade {name!r} could not be loaded from {CASCADE_DIR}")
        _classifiers[name] = classifier
    return _classifiers[name]


def _gray(rgba: MatLike) -> MatLike:
    return cv2.cvtColor(rgba, cv2.COLOR_RGBA2GRAY)


def _window_image(rgba: Rgba, region: Box, size: tuple[int, int] | None) -> MatLike:
    """The detection image's pixels inside ``region``: converted and reduced from the window's
    own part of the frame where the reduction's grid allows it (``window.source_rect``), else
    cropped from the whole frame's detection image."""
    if size is None:
        return _gray(window.crop(rgba, region))
    height, width = rgba.shape[:2]
    rects = window.source_rect(region, width, height, size)
    if rects is None:
        return window.crop(cv2.resize(_gray(rgba), size, interpolation=cv2.INTER_AREA), region)
    (x0, y0, w0, h0), source = rects
    part = cv2.resize(_gray(window.crop(rgba, source)), (w0, h0), interpolation=cv2.INTER_AREA)
    x, y, w, h = region
    return window.crop(part, (x - x0, y - y0, w, h))


def _detect_cascade(
    params: CascadeParams, rgba: Rgba, around: Box | None, full_resolution: bool
) -> Detection:
    region = None
    ox = oy = 0
    min_size, max_size = params.min_size, params.max_size
    if around is None:
        gray, factor = _reduce(_gray(rgba), params.detect_width)
    else:
        height, width = rgba.shape[:2]
        size = None if full_resolution else _reduction(width, height, params.detect_width)
        factor = _factor(width, size)
        reduced_width, reduced_height = size or (width, height)
        region = window.search_region(
            around, factor, reduced_width, reduced_height, params.window_margin
        )
        if region is None:
            return Detection(boxes=[], target=None, region=region)
        ox, oy = region[:2]
        gray = _window_image(rgba, region, size)
        min_size, max_size = window.search_sizes(
            around, factor, params.window_size_ratio, min_size, max_size
        )
    boxes = _cascades(params, gray, (ox, oy), factor, min_size, max_size)
    return Detection(boxes=boxes, target=_centre_of_largest(boxes), region=region)


def _cascades(
    params: CascadeParams,
    gray: MatLike,
    origin: tuple[int, int],
    factor: float,
    min_size: tuple[int, int],
    max_size: tuple[int, int],
) -> list[Box]:
    """Every cascade's boxes in ``gray`` (an image whose pixel (0, 0) is detection-image pixel
    ``origin``), scaled to full-frame pixels by ``factor``, sorted."""
    ox, oy = origin
    boxes: list[Box] = []
    for name in params.cascades:
        found = _classifier(name).detectMultiScale(
            gray,
            scaleFactor=params.scale_factor,
            minNeighbors=params.min_neighbors,
            flags=0,
            minSize=min_size,
            maxSize=max_size,
        )
        for x, y, w, h in found:
            boxes.append(_scale_box((int(x) + ox, int(y) + oy, int(w), int(h)), factor))
    boxes.sort()
    return boxes


def _search_cascade(params: CascadeParams, rgba: Rgba, region: Box) -> Detection:
    gray = _gray(window.crop(rgba, region))
    boxes = _cascades(params, gray, region[:2], 1.0, params.min_size, params.max_size)
    return Detection(boxes=boxes, target=_centre_of_largest(boxes), region=region)


def _detect_colour(params: ColourParams, rgba: Rgba) -> Detection:
    rgb, factor = _reduce(cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB), params.detect_width)
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    mask = np.zeros(hsv.shape[:2], np.uint8)
    for r in params.hsv_ranges:
        mask = cv2.bitwise_or(mask, cv2.inRange(hsv, np.array(r.lower), np.array(r.upper)))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (params.kernel, params.kernel))
    if params.open_iterations:
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel, iterations=params.open_iterations)
    if params.close_iterations:
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel, iterations=params.close_iterations)
    count, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if count < 2:  # label 0 is the background
        return Detection(boxes=[], target=None)
    # argmax keeps the first of equal areas, as the JS loop with a strict '>' does.
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[best, cv2.CC_STAT_AREA] < params.min_area:
        return Detection(boxes=[], target=None)
    x, y, w, h = (int(v) for v in stats[best, :4])
    cx, cy = (float(v) for v in centroids[best])
    return Detection(boxes=[_scale_box((x, y, w, h), factor)], target=(cx * factor, cy * factor))


_nets: dict[str, cv2.dnn.Net] = {}


def _net(model: str) -> cv2.dnn.Net:
    """The model's network, read once per process."""
    if model not in _nets:
        _nets[model] = cv2.dnn.readNetFromTFLite(str(MODEL_DIR / model))
    return _nets[model]


def dnn_input(params: DnnParams, rgb: MatLike, fit: blazeface.Letterbox) -> MatLike:
    """The input blob of one pass: the part ``fit.region`` of the RGB frame resized into the
    input's top-left corner (INTER_AREA down, INTER_LINEAR up), the rest black, scaled to
    [-1, 1], NCHW."""
    size = params.input_size
    x, y, w, h = fit.region
    interpolation = cv2.INTER_AREA if fit.scale < 1 else cv2.INTER_LINEAR
    part = cv2.resize(
        rgb[y : y + h, x : x + w], (fit.width, fit.height), interpolation=interpolation
    )
    padded = cv2.copyMakeBorder(
        part, 0, size - fit.height, 0, size - fit.width, cv2.BORDER_CONSTANT, value=(0, 0, 0)
    )
    return cv2.dnn.blobFromImage(
        padded, 1.0 / 127.5, (size, size), (127.5, 127.5, 127.5), swapRB=False, crop=False
    )


def _dnn_faces(params: DnnParams, rgb: MatLike, parts: list[Box]) -> list[blazeface.Face]:
    """Every pass's faces over ``parts`` of the RGB frame, suppressed together."""
    net = _net(params.model)
    layers = [blazeface.AnchorLayer(a.stride, a.per_cell) for a in params.anchors]
    centres = blazeface.anchors(params.input_size, layers)
    faces: list[blazeface.Face] = []
    for part in parts:
        fit = blazeface.letterbox(part, params.input_size)
        net.setInput(dnn_input(params, rgb, fit))
        scores, raw = net.forward(net.getUnconnectedOutLayersNames())
        faces += blazeface.decode(
            np.asarray(scores, np.float64),
            np.asarray(raw, np.float64),
            centres,
            fit,
            params.score_threshold,
        )
    return blazeface.suppress(faces, params.nms_threshold, params.min_box_size)


def _dnn_detection(faces: list[blazeface.Face], region: Box | None) -> Detection:
    ordered = sorted(faces, key=lambda face: face.box)
    boxes = [face.box for face in ordered]
    return Detection(
        boxes=boxes,
        target=_centre_of_largest(boxes),
        region=region,
        scores=tuple(face.score for face in ordered),
    )


def _detect_dnn(params: DnnParams, rgba: Rgba, around: Box | None) -> Detection:
    height, width = rgba.shape[:2]
    if around is None:
        parts = blazeface.passes(width, height, params.tile_fraction, params.tile_overlap)
        return _dnn_detection(_dnn_faces(params, _rgb(rgba), parts), None)
    region = blazeface.around(around, params.window_margin, width, height)
    if region is None:
        return Detection(boxes=[], target=None, region=None)
    return _dnn_detection(_dnn_faces(params, _rgb(rgba), [region]), region)


def _search_dnn(params: DnnParams, rgba: Rgba, region: Box) -> Detection:
    x, y, w, h = region
    parts = [
        (px + x, py + y, pw, ph)
        for px, py, pw, ph in blazeface.passes(w, h, params.tile_fraction, params.tile_overlap)
    ]
    return _dnn_detection(_dnn_faces(params, _rgb(rgba), parts), region)


def _rgb(rgba: Rgba) -> MatLike:
    return cv2.cvtColor(rgba, cv2.COLOR_RGBA2RGB)


def _check(rgba: Rgba, profile: Profile) -> None:
    if rgba.dtype != np.uint8 or rgba.ndim != 3 or rgba.shape[2] != 4:
        raise ValueError(f"expected an H×W×4 uint8 RGBA frame, got {rgba.dtype} {rgba.shape}")
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r}; expected one of {PROFILES}")


def detect(
    op: AnyOperation,
    rgba: Rgba,
    profile: Profile = "default",
    around: Box | None = None,
    full_resolution: bool = False,
) -> Detection:
    """Run ``op`` on an RGBA frame (H×W×4 uint8) exactly as its OpenCV.js module does.

    ``around`` (cascade operations only): search just the window around this full-frame box;
    ``full_resolution``: that window of the frame as it is, not of the reduced detection image
    (a target locked at full resolution, app/protocol/lock.py).
    """
    _check(rgba, profile)
    if isinstance(op, CascadeOperation):
        return _detect_cascade(op.params_for(profile), rgba, around, full_resolution)
    if isinstance(op, DnnOperation):
        return _detect_dnn(op.params_for(profile), rgba, around)
    if around is not None:
        raise ValueError(f"operation {op.id!r} is not a cascade; it has no windowed search")
    return _detect_colour(op.params_for(profile), rgba)


def search(
    op: CascadeOperation | DnnOperation, rgba: Rgba, region: Box, profile: Profile = "default"
) -> Detection:
    """Search ``region`` (full-frame pixels) of an RGBA frame at full resolution, for objects
    of every size the operation looks for: where a click near no box looks
    (app/protocol/lock.py), as ``searchIn`` of the operation's OpenCV.js module does."""
    _check(rgba, profile)
    if isinstance(op, DnnOperation):
        return _search_dnn(op.params_for(profile), rgba, region)
    return _search_cascade(op.params_for(profile), rgba, region)


def look(rgba: Rgba, box: window.Box, bins: tuple[int, int]) -> list[float]:
    """The look of ``box`` in an RGBA frame, as the relay's worker takes it (``lookIn``): the
    hue × saturation histogram of the pixels under it (:func:`app.vision.lock.look_rect`) with
    ``bins`` bins each way, of OpenCV's 8-bit HSV, normalised to sum 1 (all 0 for no pixels)."""
    height, width = rgba.shape[:2]
    x, y, w, h = look_rect(box, width, height)
    if w == 0 or h == 0:
        return [0.0] * (bins[0] * bins[1])
    rgb = cv2.cvtColor(np.ascontiguousarray(rgba[y : y + h, x : x + w]), cv2.COLOR_RGBA2RGB)
    hsv = cv2.cvtColor(rgb, cv2.COLOR_RGB2HSV)
    hist = cv2.calcHist([hsv], [0, 1], None, list(bins), [0, 180, 0, 256]).flatten()
    total = float(hist.sum())
    return [float(v) / total for v in hist]
