"""``autopilot parity``: OpenCV.js in the relay's analyzer against the Python OpenCV reference.

Every image is decoded in headless Chromium and sent through the analyzer the relay uses
(``vision.js``: ImageBitmap -> worker -> OffscreenCanvas -> cv.Mat -> the operation module), and
:func:`app.vision.spec.detect` runs on exactly the RGBA pixels that the worker analysed (they come
back, unless Python's own decoding of the file has the same SHA-256), so decoding differences
between browser and Python cannot hide or fake a mismatch.

The windowed path (detect, then track: ``app/vision/window.py``) is checked too: for every
cascade or DNN operation that found a target, both sides search the window around the same box
on the same pixels, and must agree by the same rule.

Agreement rule: both sides find the same number of boxes, and the JS boxes can be paired with
distinct Python boxes so that every pair overlaps with IoU >= 0.9. For Haar cascades the boxes are
expected to be identical; the tolerance only absorbs last-bit differences in colour conversion.
An operation that scores its boxes (DNN) must also give each pair scores within 0.02.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import json
import logging
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from playwright.sync_api import Browser, Page, sync_playwright

from app.arguments import add_relay_profile
from app.chromium import launch_options
from app.protocol.opencv import OPENCV_BUILDS, RELAY_OPENCV_BUILD, OpenCvBuild
from app.protocol.relay_profiles import Profile
from app.server.config import Settings
from app.server.serve import start_in_thread
from app.vision.reference import Detection, detect
from app.vision.spec import AnyOperation, CascadeOperation, DnnOperation, Spec, load_spec

log = logging.getLogger(__name__)

IOU_THRESHOLD = 0.9
SCORE_TOLERANCE = 0.02
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".webp", ".gif"}
# Loading the 11 MB OpenCV.js and every cascade on a busy 2-core machine can take a while.
READY_TIMEOUT_MS = 180_000

Box = tuple[int, int, int, int]
# The Python reference is a pure function of an operation's parameters and the pixels: a process
# that checks the same decoded images against both OpenCV.js builds (the test suite does) runs
# it once per image. Bounded, for a long batch of images.
_REFERENCES: dict[tuple[str, str, Box | None], Detection] = {}
_REFERENCES_KEPT = 512


def iou(a: Sequence[int], b: Sequence[int]) -> float:
    """Intersection over union of two ``(x, y, w, h)`` boxes."""
    ix = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    iy = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = a[2] * a[3] + b[2] * b[3] - inter
    return inter / union if union > 0 else 0.0


def boxes_agree(
    js: Sequence[Sequence[int]],
    py: Sequence[Sequence[int]],
    js_scores: Sequence[float] = (),
    py_scores: Sequence[float] = (),
) -> bool:
    """Same count, and a one-to-one pairing in which every pair has IoU >= 0.9 and, where both
    sides scored their boxes, scores within 0.02."""
    if len(js) != len(py) or len(js_scores) != len(py_scores):
        return False
    scored = bool(js_scores)
    if scored and len(js_scores) != len(js):
        return False
    edges = [
        [
            j
            for j, p in enumerate(py)
            if iou(b, p) >= IOU_THRESHOLD
            and (not scored or abs(js_scores[i] - py_scores[j]) <= SCORE_TOLERANCE)
        ]
        for i, b in enumerate(js)
    ]
    partner: dict[int, int] = {}  # python index -> js index

    def augment(i: int, seen: set[int]) -> bool:
        # Kuhn's augmenting path: greedy pairing can fail where a perfect pairing exists.
        for j in edges[i]:
            if j not in seen:
                seen.add(j)
                if j not in partner or augment(partner[j], seen):
                    partner[j] = i
                    return True
        return False

    return all(augment(i, set()) for i in range(len(js)))


@dataclass
class Pair:
    """One image checked with one operation."""

    image: str
    op: str
    js_boxes: list[list[int]]
    py_boxes: list[list[int]]
    js_target: list[float] | None
    py_target: list[float] | None
    agree: bool
    # Each box's score where the operation scores them (DNN), else empty.
    js_scores: list[float] = field(default_factory=list)
    py_scores: list[float] = field(default_factory=list)
    # The full-frame box whose window both sides searched; None for a full-frame scan.
    around: list[int] | None = None


@dataclass
class Report:
    """Everything a parity run found."""

    images: list[str] = field(default_factory=list)
    unreadable: dict[str, str] = field(default_factory=dict)
    details: list[Pair] = field(default_factory=list)
    # The OpenCV.js build the browser side ran ("simd" or "official"; "" before it ran).
    opencv: str = ""

    @property
    def agree(self) -> int:
        """Pairs that agree."""
        return sum(p.agree for p in self.details)

    @property
    def disagree(self) -> int:
        """Pairs that do not."""
        return len(self.details) - self.agree

    @property
    def ok(self) -> bool:
        """Every image read and every pair agreed."""
        return not self.unreadable and self.disagree == 0

    def as_json(self) -> dict[str, Any]:
        """The ``--json`` object."""
        return {
            "images": self.images,
            "opencv": self.opencv,
            "pairs": len(self.details),
            "agree": self.agree,
            "disagree": self.disagree,
            "unreadable": self.unreadable,
            "details": [asdict(p) for p in self.details],
        }


class Harness:
    """The ``/parity`` page in headless Chromium, with the server behind it.

    Use :func:`open_harness`; one harness serves a whole batch of images.
    """

    def __init__(self, page: Page, spec: Spec, server_url: str) -> None:
        self.page = page
        self.spec = spec
        # The OpenCV.js build the page loaded: "simd" or "official".
        self.build: str = page.evaluate("document.body.dataset.opencv")
        # The server the page came from, for other pages in the same browser.
        self.server_url = server_url

    @contextmanager
    def on_build(self, build: OpenCvBuild) -> Iterator[Harness]:
        """A harness on another parity page in the same browser, with OpenCV.js ``build``;
        its page is closed afterwards."""
        browser = self.page.context.browser
        if browser is None:
            raise RuntimeError("the parity page has no browser")
        page = _parity_page(browser, self.server_url, build)
        try:
            yield Harness(page, self.spec, self.server_url)
        finally:
            page.close()

    def run(
        self,
        data: bytes,
        op_ids: Sequence[str],
        profile: Profile = "default",
        window_ops: Sequence[str] = (),
    ) -> tuple[np.ndarray[Any, np.dtype[np.uint8]], dict[str, Any]]:
        """Decode ``data`` in the browser and run each op; the analysed RGBA and JS results.

        Each op of ``window_ops`` that found something also searches the window around its
        largest box; its result carries ``window: {around, boxes, target}``. Raises
        ``ValueError`` when the browser cannot decode the image.

        The pixels come back from the browser only where they differ from Python's own decoding
        of ``data`` (the page compares SHA-256 digests): a large photo's RGBA through the
        DevTools protocol cost more than its analysis.
        """
        rgba, _, results = self._analyse(data, op_ids, profile, window_ops)
        return rgba, results

    def _analyse(
        self, data: bytes, op_ids: Sequence[str], profile: Profile, window_ops: Sequence[str]
    ) -> tuple[np.ndarray[Any, np.dtype[np.uint8]], str, dict[str, Any]]:
        """:meth:`run`, and the SHA-256 of the pixels it returns (the reference's memo key)."""
        here = _decoded_here(data)
        digest = None if here is None else _sha256(here)
        out = self._run_image(data, op_ids, profile, window_ops, digest or "base64")
        if out.get("sameDigest"):
            assert here is not None and digest is not None
            assert here.shape == (out["height"], out["width"], 4)
            return here, digest, out["results"]
        rgba = np.frombuffer(base64.b64decode(out["rgba"]), np.uint8)
        rgba = rgba.reshape(out["height"], out["width"], 4)
        return rgba, _sha256(rgba), out["results"]

    def results(
        self, data: bytes, op_ids: Sequence[str], profile: Profile = "default"
    ) -> dict[str, Any]:
        """Decode ``data`` in the browser and run each op; only the JS results."""
        results: dict[str, Any] = self._run_image(data, op_ids, profile, (), "none")["results"]
        return results

    def _run_image(
        self,
        data: bytes,
        op_ids: Sequence[str],
        profile: Profile,
        window_ops: Sequence[str],
        pixels: str,
    ) -> dict[str, Any]:
        out: dict[str, Any] = self.page.evaluate(
            "([data, ops, profile, windowOps, pixels]) =>"
            " window.runImage(data, ops, profile, windowOps, pixels)",
            [
                base64.b64encode(data).decode("ascii"),
                list(op_ids),
                profile,
                list(window_ops),
                pixels,
            ],
        )
        if "unreadable" in out:
            raise ValueError(f"the browser cannot decode it ({out['unreadable']})")
        return out

    def analyze_pixels(
        self,
        rgba: np.ndarray[Any, np.dtype[np.uint8]],
        op_id: str,
        profile: str = "default",
        *,
        around: Sequence[int] | None = None,
        track: bool = False,
    ) -> dict[str, Any]:
        """Run ``op_id`` in the browser on exactly these RGBA pixels (H×W×4).

        ``around``: search only the window around this full-frame box; ``track``: detect,
        then track across the calls that set it. Returns ``{boxes, target, scan, region}``.
        """
        height, width = rgba.shape[:2]
        options = {"profile": profile, "track": track, "around": list(around) if around else None}
        result: dict[str, Any] = self.page.evaluate(
            "([data, w, h, op, options]) => window.runPixels(data, w, h, op, options)",
            [base64.b64encode(rgba.tobytes()).decode("ascii"), width, height, op_id, options],
        )
        return result

    def reset_tracking(self) -> None:
        """Forget the analyzer's tracked targets: the next tracked call is a full scan."""
        self.page.evaluate("() => window.analyzer.resetTracking()")

    def check(
        self, path: Path, op_ids: Sequence[str], report: Report, profile: Profile = "default"
    ) -> None:
        """Check one image with every op in ``op_ids``; results are added to ``report``."""
        name = str(path)
        cascades = [
            i for i in op_ids if isinstance(self.spec.op(i), CascadeOperation | DnnOperation)
        ]
        try:
            rgba, digest, results = self._analyse(path.read_bytes(), op_ids, profile, cascades)
        except (OSError, ValueError) as exc:
            report.unreadable[name] = f"cannot read image {name}: {exc}"
            return
        report.images.append(name)
        # The pixels' identity (shape and digest), for the reference's results.
        pixels = f"{rgba.shape} {digest}"
        for op_id in op_ids:
            op = self.spec.op(op_id)
            py = _reference(op, rgba, pixels, profile)
            js = results[op_id]
            report.details.append(_pair(name, op_id, js, py))
            windowed = js.get("window")
            if windowed is not None:
                # The windowed path: both sides searched the window around the same box.
                around = windowed["around"]
                py = _reference(op, rgba, pixels, profile, tuple(around))
                report.details.append(_pair(name, op_id, windowed, py, around=around))


def _sha256(pixels: np.ndarray[Any, np.dtype[np.uint8]]) -> str:
    """SHA-256 in hex of an array's bytes, as the parity page computes it."""
    return hashlib.sha256(np.ascontiguousarray(pixels).data).hexdigest()


def _decoded_here(data: bytes) -> np.ndarray[Any, np.dtype[np.uint8]] | None:
    """``data`` decoded by Python OpenCV, as RGBA; None where it cannot decode it."""
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        return None
    return np.asarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGBA), np.uint8)


def _reference(
    op: AnyOperation,
    rgba: np.ndarray[Any, np.dtype[np.uint8]],
    pixels: str,
    profile: Profile,
    around: Box | None = None,
) -> Detection:
    """:func:`detect`, once per parameters, pixels (``pixels``: their digest) and window."""
    key = (op.kind + op.params_for(profile).model_dump_json(), pixels, around)
    found = _REFERENCES.get(key)
    if found is None:
        found = detect(op, rgba, profile, around=around)
        if len(_REFERENCES) >= _REFERENCES_KEPT:
            del _REFERENCES[next(iter(_REFERENCES))]
        _REFERENCES[key] = found
    return found


def _pair(
    image: str,
    op_id: str,
    js: dict[str, Any],
    py: Detection,
    around: list[int] | None = None,
) -> Pair:
    js_target = js["target"]
    py_boxes = [list(b) for b in py.boxes]
    js_scores = js.get("scores") or []
    py_scores = list(py.scores)
    return Pair(
        image=image,
        op=op_id,
        js_boxes=js["boxes"],
        py_boxes=py_boxes,
        js_target=[js_target["x"], js_target["y"]] if js_target else None,
        py_target=list(py.target) if py.target else None,
        agree=boxes_agree(js["boxes"], py_boxes, js_scores, py_scores),
        around=around,
        js_scores=js_scores,
        py_scores=py_scores,
    )


def _parity_page(browser: Browser, server_url: str, build: OpenCvBuild | None) -> Page:
    """A parity page whose analyzer is ready, on OpenCV.js ``build`` (None: the relay's)."""
    page = browser.new_page()
    page.on("console", lambda m: log.debug("page console: %s", m.text))
    # No ?opencv= on the relay's page either (app.relay.page.relay_url).
    page.goto(f"{server_url}/parity" + ("" if build is None else f"?opencv={build}"))
    # A function, not an expression: Playwright evals a bare expression inside the page, which
    # the page's CSP (no 'unsafe-eval') refuses.
    page.wait_for_function(
        "() => document.body.dataset.ready", timeout=READY_TIMEOUT_MS, polling=100
    )
    if page.evaluate("document.body.dataset.ready") != "true":
        state = page.text_content("#state")
        page.close()
        raise RuntimeError(f"parity page: {state}")
    return page


@contextmanager
def open_harness(
    settings: Settings | None = None, build: OpenCvBuild | None = None
) -> Iterator[Harness]:
    """Start the server and headless Chromium on the parity page, with the OpenCV.js ``build``
    (None: the build the relay page loads, by the same rule); stop both afterwards."""
    settings = settings or Settings()
    spec = load_spec(settings.operations_spec)
    server = start_in_thread(settings)
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(**launch_options())
            try:
                yield Harness(_parity_page(browser, server.url, build), spec, server.url)
            finally:
                browser.close()
    finally:
        server.stop()


def expand(paths: Sequence[Path]) -> tuple[list[Path], dict[str, str]]:
    """Image files named directly or found (non-recursively) in folders, and missing paths."""
    images: list[Path] = []
    missing: dict[str, str] = {}
    for path in paths:
        if path.is_dir():
            images.extend(p for p in sorted(path.iterdir()) if p.suffix.lower() in IMAGE_SUFFIXES)
        elif path.exists():
            images.append(path)
        else:
            missing[str(path)] = f"cannot read image {path}: no such file or folder"
    return images, missing


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot parity``."""
    parser.add_argument("paths", nargs="*", type=Path, metavar="PATH", help="images or folders")
    parser.add_argument("--op", default="all", help="operation id, or 'all' (default)")
    add_relay_profile(parser, "relay profile whose parameters to check")
    parser.add_argument(
        "--opencv",
        choices=OPENCV_BUILDS,
        help="OpenCV.js build: simd (scripts/build-opencv-js) or official (npm); default: the"
        f" one the relay page loads ({RELAY_OPENCV_BUILD})",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _format_boxes(boxes: Sequence[Sequence[int]]) -> str:
    return "[" + " ".join("({},{},{},{})".format(*b) for b in boxes) + "]"


def run(args: argparse.Namespace) -> int:
    """Check every image with the chosen operations; non-zero when anything disagrees."""
    if not args.paths:
        sys.stderr.write(
            "usage: autopilot parity PATH... [--op ID|all] [--json]\n"
            "autopilot parity: error: give at least one image or folder\n"
        )
        return 2
    settings = Settings()
    spec = load_spec(settings.operations_spec)
    known = [op.id for op in spec.operations]
    if args.op != "all" and args.op not in known:
        sys.stderr.write(f"autopilot parity: unknown operation {args.op!r}; known: {known}\n")
        return 2
    op_ids = known if args.op == "all" else [args.op]
    images, missing = expand(args.paths)
    report = Report(unreadable=dict(missing))
    if images:
        with open_harness(settings, args.opencv) as harness:
            report.opencv = harness.build
            for path in images:
                harness.check(path, op_ids, report, args.profile)
    if args.json:
        sys.stdout.write(json.dumps(report.as_json(), indent=2) + "\n")
    else:
        for pair in report.details:
            verdict = "agree" if pair.agree else "DISAGREE"
            where = " (window around ({},{},{},{}))".format(*pair.around) if pair.around else ""
            sys.stdout.write(
                f"{pair.image} {pair.op}{where}: {verdict}\n"
                f"    js     {_format_boxes(pair.js_boxes)}\n"
                f"    python {_format_boxes(pair.py_boxes)}\n"
            )
        sys.stdout.write(
            f"{len(report.images)} images, {len(report.details)} pairs"
            f" (OpenCV.js {report.opencv or 'not loaded'}): "
            f"{report.agree} agree, {report.disagree} disagree\n"
        )
    for message in report.unreadable.values():
        sys.stderr.write(f"autopilot parity: {message}\n")
    return 0 if report.ok else 1
