"""The operations spec (``app/vision/operations.json``): models, loading and validation.

One declarative file configures every operation for both sides: the relay's OpenCV.js modules
(``app/static/js/worker/operations/``) fetch it from ``/operations.json`` with every default filled
in and every profile's parameters already merged, and :func:`app.vision.reference.detect` runs the
same pipeline with Python OpenCV so parity checks compare like with like. The spec is validated once
at start-up: a cascade file that the pinned OpenCV wheel does not ship, or a module that does not
exist, stops the server with a message naming the entry.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Annotated, Any, Generic, Literal, TypeVar

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    model_validator,
)
from pydantic.alias_generators import to_camel

from app.protocol.errors import describe
from app.protocol.relay_profiles import PROFILES, Profile
from app.resources import OPERATION_MODULES_DIR, STATIC_DIR


def _cascade_dir() -> Path:
    """``cv2.data.haarcascades`` of the pinned wheel, found without importing cv2 (the server
    serves the files; only the reference pipeline needs OpenCV itself)."""
    found = importlib.util.find_spec("cv2")
    if found is None or not found.submodule_search_locations:
        raise RuntimeError("opencv-python-headless is not installed: no Haar cascade files")
    return Path(next(iter(found.submodule_search_locations))) / "data"


CASCADE_DIR = _cascade_dir()
# Where the vendored DNN models are (served at /static/vendor/).
MODEL_DIR = STATIC_DIR / "vendor"

# Taller than any target an operation finds (a person, a vehicle): a larger declared height is a
# unit mistake (millimetres, centimetres), refused at start-up.
MAX_TARGET_HEIGHT_M = 10.0


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
    # The window looks only for sizes within window_size_ratio of the last target's: per
    # operation, small enough to skip the costly small scales, large enough that the window
    # still finds the box a search of every size finds (docs/bench/relay-cost.md). The margin
    # is how far the target may move between two snapshots and stay in the window; past it the
    # window misses and the full scan finds the target on the same snapshot, at its price.
    full_scan_every: int = Field(1, ge=1)
    window_margin: float = Field(0.5, gt=0.0)
    window_size_ratio: float = Field(2.0, gt=1.0)


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


class AnchorLayer(_Model):
    """``perCell`` anchors of a fixed size at the centre of each cell of a ``stride``-pixel grid
    over the model's square input (app/vision/blazeface.py anchors)."""

    stride: int = Field(gt=0)
    per_cell: int = Field(gt=0)


class DnnParams(_Model):
    """A BlazeFace model through OpenCV's DNN module, decoded by app/vision/blazeface.py and
    its JS twin. Sizes are in frame pixels unless said otherwise."""

    # A file of app/static/vendor (scripts/vendor fetched it; VENDORED.json records it).
    model: str = Field(pattern=r"^[a-z0-9_]+\.tflite$")
    # The model's square input, in pixels, and its anchors, in output order.
    input_size: int = Field(gt=0)
    anchors: list[AnchorLayer] = Field(min_length=1)
    score_threshold: float = Field(0.5, gt=0.0, lt=1.0)
    # Greedy NMS: a box overlapping a better one by more than this IoU is dropped.
    nms_threshold: float = Field(0.3, gt=0.0, le=1.0)
    # Boxes less tall than this are dropped (before NMS).
    min_box_size: int = Field(0, ge=0)
    # A full scan is the whole frame letterboxed into the input, then square tiles this share of
    # the frame's width wide (0: none) overlapping by tile_overlap of a tile, where faces too
    # small for the whole-frame pass are at the model's scale (docs/performance.md says why).
    tile_fraction: float = Field(0.0, ge=0.0, le=1.0)
    tile_overlap: float = Field(0.25, ge=0.0, lt=1.0)
    # Detect, then track (app/vision/window.py): between full scans one forward pass over a
    # square around the last target, window_margin of its size on each side.
    full_scan_every: int = Field(1, ge=1)
    window_margin: float = Field(0.5, gt=0.0)


P = TypeVar("P", CascadeParams, ColourParams, DnnParams)


class _OperationBase(_Model, Generic[P]):
    id: str = Field(pattern=r"^[a-z][a-z0-9_]*$")
    label: str
    description: str
    module: str = Field(pattern=r"^[a-z][a-z0-9_]*\.js$")
    # The real height (m) of what the operation's box spans (a face's box, a flame): a vehicle
    # that carries its camera reads the target's range from its box's apparent height
    # (vehicle_agent/core/control.py, the onboard law). Goals carry it with the box.
    target_height_m: float = Field(gt=0.0, le=MAX_TARGET_HEIGHT_M, allow_inf_nan=False, strict=True)
    params: P
    # Parameter overrides for the relay's thesis profile (full resolution, tutorial values).
    thesis: dict[str, Any] = Field(default_factory=dict)
    _thesis_params: P = PrivateAttr()

    @model_validator(mode="after")
    def _merge_thesis(self) -> _OperationBase[P]:
        merged = self.params.model_dump(by_alias=True) | self.thesis
        self._thesis_params = type(self.params).model_validate(merged)
        return self

    def params_for(self, profile: Profile) -> P:
        """Parameters of a relay profile: ``thesis`` applies the overrides."""
        return self._thesis_params if profile == "thesis" else self.params

    def params_by_profile(self) -> dict[str, dict[str, Any]]:
        """Every profile's merged parameters, as the browser receives them."""
        return {p: self.params_for(p).model_dump(by_alias=True, mode="json") for p in PROFILES}


class CascadeOperation(_OperationBase[CascadeParams]):
    """An operation built on Haar cascades."""

    kind: Literal["cascade"]


class ColourOperation(_OperationBase[ColourParams]):
    """An operation built on colour segmentation."""

    kind: Literal["colour"]


class DnnOperation(_OperationBase[DnnParams]):
    """An operation built on a DNN face model (BlazeFace)."""

    kind: Literal["dnn"]


AnyOperation = CascadeOperation | ColourOperation | DnnOperation
Operation = Annotated[AnyOperation, Field(discriminator="kind")]


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

    def op(self, op_id: str) -> AnyOperation:
        """The operation with this id; ``KeyError`` naming it otherwise."""
        for op in self.operations:
            if op.id == op_id:
                return op
        raise KeyError(f"unknown operation {op_id!r}")

    def for_browser(self) -> dict[str, Any]:
        """The spec as ``/operations.json`` serves it: every default filled in and each
        operation's ``paramsByProfile``, so the browser never merges or guesses."""
        data = self.model_dump(by_alias=True, mode="json")
        for entry, op in zip(data["operations"], self.operations, strict=True):
            entry["paramsByProfile"] = op.params_by_profile()
        return data

    def cascade_files(self) -> set[str]:
        """Every cascade file any profile of any operation names."""
        files: set[str] = set()
        for op in self.operations:
            if isinstance(op, CascadeOperation):
                for profile in PROFILES:
                    files.update(op.params_for(profile).cascades)
        return files


def load_spec(path: Path, module_dir: Path = OPERATION_MODULES_DIR) -> Spec:
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
        raise SpecError(f"operations spec {path}: {describe(exc)}") from exc
    for op in spec.operations:
        if not (module_dir / op.module).is_file():
            raise SpecError(
                f"operations spec {path}: operation {op.id!r} names module {op.module!r}, "
                f"which is not in {module_dir}"
            )
        if isinstance(op, DnnOperation):
            for profile in PROFILES:
                model = op.params_for(profile).model
                if not (MODEL_DIR / model).is_file():
                    raise SpecError(
                        f"operations spec {path}: operation {op.id!r} needs model {model!r}, "
                        f"which is not in {MODEL_DIR} (scripts/vendor fetches it)"
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
