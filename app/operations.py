"""The operations spec (``app/operations.json``), its HTTP routes, and the Python reference.

One declarative file configures every operation for both sides: the relay's OpenCV.js modules
(``app/static/js/operations/``) fetch it from ``/operations.json`` with every default filled in,
and :func:`detect` runs the same pipeline with Python OpenCV so parity checks compare like with
like. The spec is validated once at start-up: a cascade file that the pinned OpenCV wheel does not
ship, or a module that does not exist, stops the server with a message naming the entry.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import cv2
import numpy as np
import numpy.typing as npt
from cv2.typing import MatLike
from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse
from fastapi.templating import Jinja2Templates
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    model_validator,
)
from pydantic.alias_generators import to_camel

from app.config import PACKAGE_DIR
from app.vision import window

# cv2.data.haarcascades of the pinned wheel (its type stubs omit the cv2.data module).
CASCADE_DIR = Path(cv2.__file__).resolve().parent / "data"
MODULE_DIR = PACKAGE_DIR / "static" / "js" / "operations"
PROFILES = ("default", "thesis")

Rgba = npt.NDArray[np.uint8]
Box = tuple[int, int, int, int]


class SpecError(ValueError):
    """The operations spec cannot be used; the message names the file and the entry."""


class _Model(BaseModel):
    # The JSON keys follow OpenCV.js's own names (scaleFactor, minNeighbors); typos are refused.
    model_config = ConfigDict(alias_generator=to_camel, populate_by_name=True, extra="forbid")


class CascadeParams(_Model):
    """Haar cascade detection. Sizes are in pixels of the reduced (detection) image."""

    cascades: list[str] = Field(min_length=1)
    scale_factor: float = Field(1.1, gt=1.0)
    min_neighbors: int = Field(3, ge=0)
    min_size: tuple[int, int] = (0, 0)
    max_size: tuple[int, int] = (0, 0)
    # The frame is reduced to this width before detection (INTER_AREA); null: full resolution.
    detect_width: int | None = Field(None, gt=0)
    # Detect, then track (app/vision/window.py): after a hit, snapshots search a window around
    # the last target grown by window_margin of its size on each side; the whole frame is
    # scanned every full_scan_every snapshots and whenever the window finds nothing. 1: off.
    full_scan_every: int = Field(1, ge=1)
    window_margin: float = Field(0.5, gt=0.0)


class HsvRange(_Model):
    """Inclusive OpenCV HSV bounds (H in 0..180, S and V in 0..255)."""

    lower: tuple[int, int, int]
    upper: tuple[int, int, int]


class ColourParams(_Model):
    """Colour segmentation: union of HSV ranges, open then close, the largest region."""

    hsv_ranges: list[HsvRange] = Field(min_length=1)
    kernel: int = Field(5, ge=1)
    open_iterations: int = Field(1, ge=0)
    close_iterations: int = Field(1, ge=0)
    # Smallest region kept, in pixels of the reduced (detection) image.
    min_area: int = Field(50, ge=1)
    detect_width: int | None = Field(None, gt=0)


class _OperationBase(_Model):
    id: str = Field(pattern=r"^[a-z][a-z0-9_]*$")
    label: str
    description: str
    module: str = Field(pattern=r"^[a-z][a-z0-9_]*\.js$")
    # Parameter overrides for the relay's thesis profile (full resolution, tutorial values).
    thesis: dict[str, Any] = Field(default_factory=dict)


class CascadeOperation(_OperationBase):
    """An operation built on Haar cascades."""

    kind: Literal["cascade"]
    params: CascadeParams
    _thesis_params: CascadeParams = PrivateAttr()

    @model_validator(mode="after")
    def _merge_thesis(self) -> CascadeOperation:
        merged = self.params.model_dump(by_alias=True) | self.thesis
        self._thesis_params = CascadeParams.model_validate(merged)
        return self

    def params_for(self, profile: str) -> CascadeParams:
        """Parameters of a relay profile: ``thesis`` applies the overrides."""
        return self._thesis_params if profile == "thesis" else self.params


class ColourOperation(_OperationBase):
    """An operation built on colour segmentation."""

    kind: Literal["colour"]
    params: ColourParams
    _thesis_params: ColourParams = PrivateAttr()

    @model_validator(mode="after")
    def _merge_thesis(self) -> ColourOperation:
        merged = self.params.model_dump(by_alias=True) | self.thesis
        self._thesis_params = ColourParams.model_validate(merged)
        return self

    def params_for(self, profile: str) -> ColourParams:
        """Parameters of a relay profile: ``thesis`` applies the overrides."""
        return self._thesis_params if profile == "thesis" else self.params


Operation = Annotated[CascadeOperation | ColourOperation, Field(discriminator="kind")]


class Spec(_Model):
    """The whole spec: operations in the order the client lists them, and the default."""

    default: str
    operations: list[Operation] = Field(min_length=1)

    @model_validator(mode="after")
    def _check_ids(self) -> Spec:
        ids = [op.id for op in self.operations]
        duplicates = sorted({i for i in ids if ids.count(i) > 1})
        if duplicates:
            raise ValueError(f"duplicate operation id(s): {', '.join(duplicates)}")
        if self.default not in ids:
            raise ValueError(f"default operation {self.default!r} is not one of {ids}")
        return self

    def op(self, op_id: str) -> CascadeOperation | ColourOperation:
        """The operation with this id; ``KeyError`` naming it otherwise."""
        for op in self.operations:
            if op.id == op_id:
                return op
        raise KeyError(f"unknown operation {op_id!r}")

    def cascade_files(self) -> set[str]:
        """Every cascade file any profile of any operation names."""
        files: set[str] = set()
        for op in self.operations:
            if isinstance(op, CascadeOperation):
                for profile in PROFILES:
                    files.update(op.params_for(profile).cascades)
        return files


def load_spec(path: Path, module_dir: Path = MODULE_DIR) -> Spec:
    """Read and validate the spec; :class:`SpecError` says what is wrong and where."""
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SpecError(f"operations spec {path}: cannot read it: {exc.strerror}") from exc
    except json.JSONDecodeError as exc:
        raise SpecError(f"operations spec {path}: not valid JSON: {exc}") from exc
    try:
        spec = Spec.model_validate(raw)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in err['loc'])}: {err['msg']}" for err in exc.errors()
        )
        raise SpecError(f"operations spec {path}: {problems}") from exc
    for op in spec.operations:
        if not (module_dir / op.module).is_file():
            raise SpecError(
                f"operations spec {path}: operation {op.id!r} names module {op.module!r}, "
                f"which is not in {module_dir}"
            )
        if isinstance(op, CascadeOperation):
            for profile in PROFILES:
                for name in op.params_for(profile).cascades:
                    if Path(name).name != name or not (CASCADE_DIR / name).is_file():
                        raise SpecError(
                            f"operations spec {path}: operation {op.id!r} needs cascade "
                            f"{name!r}, which the pinned OpenCV wheel does not ship in "
                            f"{CASCADE_DIR}"
                        )
    return spec


# --- Python reference pipeline: the same OpenCV calls as app/static/js/operations/ ----------


@dataclass(frozen=True)
class Detection:
    """Boxes ``(x, y, w, h)`` in full-frame pixels, sorted; the target point or None."""

    boxes: list[Box]
    target: tuple[float, float] | None
    # The window searched, in detection-image pixels; None for a full-frame scan.
    region: Box | None = None


def _reduction(width: int, height: int, detect_width: int | None) -> tuple[int, int] | None:
    """Size of the detection image, or None when the frame is used as it is.

    Rounding is written out (floor of x + 0.5) because JavaScript's Math.round and Python's
    round() differ on halves; both sides compute the same doubles.
    """
    if detect_width is None or width <= detect_width:
        return None
    return detect_width, math.floor(height * detect_width / width + 0.5)


def _reduce(image: MatLike, detect_width: int | None) -> tuple[MatLike, float]:
    """The detection image (reduced with INTER_AREA when wider than ``detect_width``) and the
    factor that scales its coordinates back to the full frame."""
    height, width = image.shape[:2]
    size = _reduction(width, height, detect_width)
    if size is None:
        return image, 1.0
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA), width / size[0]


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


def _detect_cascade(params: CascadeParams, rgba: Rgba, around: Box | None) -> Detection:
    gray, factor = _reduce(cv2.cvtColor(rgba, cv2.COLOR_RGBA2GRAY), params.detect_width)
    region = None
    ox = oy = 0
    if around is not None:
        height, width = gray.shape[:2]
        region = window.search_region(around, factor, width, height, params.window_margin)
        if region is None:
            return Detection(boxes=[], target=None, region=region)
        ox, oy = region[:2]
        gray = window.crop(gray, region)
    boxes: list[Box] = []
    for name in params.cascades:
        found = _classifier(name).detectMultiScale(
            gray,
            scaleFactor=params.scale_factor,
            minNeighbors=params.min_neighbors,
            flags=0,
            minSize=params.min_size,
            maxSize=params.max_size,
        )
        for x, y, w, h in found:
            boxes.append(_scale_box((int(x) + ox, int(y) + oy, int(w), int(h)), factor))
    boxes.sort()
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


def detect(
    op: CascadeOperation | ColourOperation,
    rgba: Rgba,
    profile: str = "default",
    around: Box | None = None,
) -> Detection:
    """Run ``op`` on an RGBA frame (H×W×4 uint8) exactly as its OpenCV.js module does.

    ``around`` (cascade operations only): search just the window around this full-frame box.
    """
    if rgba.dtype != np.uint8 or rgba.ndim != 3 or rgba.shape[2] != 4:
        raise ValueError(f"expected an H×W×4 uint8 RGBA frame, got {rgba.dtype} {rgba.shape}")
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r}; expected one of {PROFILES}")
    if isinstance(op, CascadeOperation):
        return _detect_cascade(op.params_for(profile), rgba, around)
    if around is not None:
        raise ValueError(f"operation {op.id!r} is not a cascade; it has no windowed search")
    return _detect_colour(op.params_for(profile), rgba)


# --- HTTP -----------------------------------------------------------------------------------

router = APIRouter()
_templates = Jinja2Templates(directory=PACKAGE_DIR / "templates")


def _spec(request: Request) -> Spec:
    spec: Spec = request.app.state.operations
    return spec


@router.get("/operations.json")
async def operations_json(request: Request) -> JSONResponse:
    """The validated spec with every default filled in: the browser never guesses a default."""
    return JSONResponse(_spec(request).model_dump(by_alias=True, mode="json"))


@router.get("/cascades/{name}")
async def cascade(name: str, request: Request) -> FileResponse:
    """A cascade XML from the pinned OpenCV wheel; only files the spec names."""
    if name not in _spec(request).cascade_files():
        raise HTTPException(status_code=404, detail=f"no operation uses cascade {name!r}")
    return FileResponse(CASCADE_DIR / name, media_type="application/xml")


@router.get("/parity", response_class=HTMLResponse)
async def parity_page(request: Request) -> HTMLResponse:
    """Harness page for ``autopilot parity``: the relay's analyzer, driven from Python."""
    return _templates.TemplateResponse(request, "parity.html", {})
