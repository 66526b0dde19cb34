"""OpenCV.js in the relay's analyzer agrees with the Python reference on the same pixels.

One headless Chromium serves the whole batch: every photo and every generated frame,
with every operation of the spec.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from app.protocol.opencv import OPENCV_BUILDS, RELAY_OPENCV_BUILD
from app.relay.page import relay_url
from app.resources import OPERATIONS_SPEC
from app.tools import parity
from app.tools.bench import faces
from app.vision import reference, window
from app.vision.spec import CascadeOperation, DnnOperation, load_spec
from tests.helpers.harness import open_harness
from tests.vision.frames import FACES, clip_stills, write_generated_frames
from vehicle_agent.video import FixedPath, SyntheticVideo

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SPEC = load_spec(OPERATIONS_SPEC)
# The operations every photo and frame goes through; face_dnn's full scan (13 forward passes) is
# too slow in OpenCV.js for the whole batch, so it has its own test on a sample of each source.
ALL_OPS = [o.id for o in SPEC.operations if not isinstance(o, DnnOperation)]
DNN_STILLS = ("two_people.jpg", "obama_partial_face.jpg", "kit_with_rose.jpg")


@pytest.fixture(scope="module")
def harness() -> Iterator[parity.Harness]:
    """The harness as `autopilot parity` opens it by default: on the relay's build."""
    with open_harness() as opened:
        yield opened


@pytest.fixture(scope="module")
def other_build(harness: parity.Harness) -> Iterator[parity.Harness]:
    """The build the relay does not load: still vendored and benchmarked (`autopilot bench
    --opencv-builds`), still checked where the two builds have disagreed."""
    (other,) = [build for build in OPENCV_BUILDS if build != RELAY_OPENCV_BUILD]
    with harness.on_build(other) as opened:
        assert opened.build == other  # loaded, not fallen back to the relay's
        yield opened


def test_parity_checks_the_build_the_relay_loads(harness: parity.Harness) -> None:
    """The page `autopilot relay` opens and `autopilot parity` with its defaults, in one
    Chromium, run the same OpenCV.js build: the one app/protocol/opencv.py names."""
    browser = harness.page.context.browser
    assert browser is not None
    relay = browser.new_page()
    try:
        relay.goto(relay_url(harness.server_url, "builds", "relay", "default"))
        relay.wait_for_function(
            "() => window.autopilotStatus?.opencvBuild", timeout=parity.READY_TIMEOUT_MS
        )
        assert relay.evaluate("() => window.autopilotStatus.opencvBuild") == harness.build
    finally:
        relay.close()
    assert harness.build == RELAY_OPENCV_BUILD


def describe(report: parity.Report) -> str:
    lines = [
        f"{p.image} {p.op}: js {p.js_boxes} python {p.py_boxes}"
        for p in report.details
        if not p.agree
    ]
    return "\n".join(lines + list(report.unreadable.values()))


def test_every_shared_photo_with_every_operation(harness: parity.Harness) -> None:
    images, missing = parity.expand([FACES])
    assert not missing and len(images) >= 10
    report = parity.Report()
    for path in images:
        harness.check(path, ALL_OPS, report)
    assert report.ok, describe(report)
    full = [p for p in report.details if p.around is None]
    assert len(full) == len(images) * len(ALL_OPS)
    # Parity of empty lists proves nothing: the photos must exercise the detectors.
    found = {op: sum(bool(p.js_boxes) for p in full if p.op == op) for op in ALL_OPS}
    assert found["face"] >= len(images) // 2, found
    # Every cascade hit was checked again through the windowed path, which found it too.
    windowed = [p for p in report.details if p.around is not None]
    cascade_hits = [p for p in full if p.js_boxes and p.op != "fire"]
    assert len(windowed) == len(cascade_hits)
    assert sum(bool(p.js_boxes) for p in windowed) >= len(windowed) * 3 // 4


def test_generated_frames_with_every_operation(harness: parity.Harness, tmp_path: Path) -> None:
    frames = write_generated_frames(tmp_path)
    report = parity.Report()
    for path in frames:
        harness.check(path, ALL_OPS, report)
    assert report.ok, describe(report)
    by_name = {(Path(p.image).stem, p.op): p for p in report.details}
    faces_found = sum(bool(by_name[(f.stem, "face")].js_boxes) for f in frames if "face" in f.stem)
    flames_found = sum(
        bool(by_name[(f.stem, "fire")].js_boxes) for f in frames if "flame" in f.stem
    )
    assert faces_found >= 8 and flames_found == 6, (faces_found, flames_found)


# Stills of the clip where a reduction that rounds its ties up instead of to even (the SIMD
# build's INTER_AREA did, 640 -> 480 for face_small) finds a box too many, one too few, none.
TIE_STILLS = (30, 245, 270)


@pytest.mark.parametrize("fixture", ["harness", "other_build"])
def test_clip_stills_whose_reduction_has_ties(
    fixture: str, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    harness: parity.Harness = request.getfixturevalue(fixture)
    report = parity.Report()
    for index, frame in zip(TIE_STILLS, clip_stills(TIE_STILLS), strict=True):
        path = tmp_path / f"clip-{index}.png"
        cv2.imwrite(str(path), frame)
        harness.check(path, ["face_small"], report)
    assert report.ok, describe(report)
    # Not agreement on nothing: the stills hold faces.
    assert sum(len(p.py_boxes) for p in report.details if p.around is None) >= 2


def test_thesis_profile_on_a_few_photos(harness: parity.Harness) -> None:
    report = parity.Report()
    for name in ("obama-480p.jpg", "two_people.jpg", "alex-lacamoire.png"):
        harness.check(FACES / name, ALL_OPS, report, profile="thesis")
    assert report.ok, describe(report)


def test_tracked_sequence_agrees_scan_for_scan(harness: parity.Harness) -> None:
    """Detect, then track in the analyzer against window.step with the reference, frame by
    frame on the same pixels: the same full/window decisions, the same boxes, the face found
    again on the frame it jumped."""
    op = SPEC.op("face")
    assert isinstance(op, CascadeOperation)
    every = op.params.full_scan_every
    path = FixedPath(0.25, 0.42)
    video = SyntheticVideo(path=path)
    jump = every + 3
    tracker = window.Tracker(every)
    harness.reset_tracking()
    js_scans, py_scans = [], []
    for i in range(every + 6):
        if i == jump:
            path.x = 0.75
        rgba = cv2.cvtColor(video.render(i), cv2.COLOR_RGB2RGBA)
        js = harness.analyze_pixels(rgba, "face", track=True)
        py, scan = window.step(
            tracker, lambda box, rgba=rgba: reference.detect(op, rgba, around=box)
        )
        js_scans.append(js["scan"])
        py_scans.append(scan)
        assert parity.boxes_agree(js["boxes"], py.boxes), (i, js, py)
        assert js["region"] == (list(py.region) if py.region else None), (i, js, py)
        cx, cy = video.face_centre(i)
        x, y, w, h = js["boxes"][0]
        assert x <= cx <= x + w and y <= cy <= y + h, (i, js)
    assert js_scans == py_scans
    assert js_scans[: every + 1] == ["full"] + ["window"] * (every - 1) + ["full"]
    assert js_scans[jump - 1 : jump + 2] == ["window", "full", "window"]


@pytest.mark.parametrize("fixture", ["harness", "other_build"])
def test_face_dnn_agrees_on_stills_the_clip_and_bench_frames(
    fixture: str, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    """face_dnn on both OpenCV.js builds against Python OpenCV: every box at IoU >= 0.9 and
    every score within 0.02, on shared photos (a partial face among them), a still of the clip
    and a faces-bench frame with a small tilted face; the window around each face too."""
    harness: parity.Harness = request.getfixturevalue(fixture)
    (still,) = clip_stills([245])
    cv2.imwrite(str(tmp_path / "clip-245.png"), still)
    photo = faces.photos(FACES, ["obama.jpg"])[0]
    rgba, _ = faces.place(photo, 32, 30, (400.0, 300.0))
    cv2.imwrite(str(tmp_path / "bench-32px-30deg.png"), cv2.cvtColor(rgba, cv2.COLOR_RGBA2BGR))
    paths = [FACES / name for name in DNN_STILLS]
    paths += [tmp_path / "clip-245.png", tmp_path / "bench-32px-30deg.png"]
    report = parity.Report()
    for path in paths:
        harness.check(path, ["face_dnn"], report)
    assert report.ok, describe(report)
    full = [p for p in report.details if p.around is None]
    # Every source holds faces, each scored on both sides.
    assert all(p.js_boxes and len(p.js_scores) == len(p.js_boxes) for p in full), describe(report)
    assert len(report.details) == 2 * len(full)  # each checked through its window too


def test_unreadable_image_is_reported_by_name(harness: parity.Harness, tmp_path: Path) -> None:
    bad = tmp_path / "not-a-picture.png"
    bad.write_bytes(b"this is text")
    report = parity.Report()
    harness.check(bad, ["face"], report)
    assert not report.ok
    assert "not-a-picture.png" in report.unreadable[str(bad)]


def test_the_reference_gets_the_pixels_the_browser_analysed(harness: parity.Harness) -> None:
    # An opaque photo decodes alike on both sides: the page confirms the digest and sends no
    # pixels, and they are Python's own decoding.
    photo = (FACES / "obama.jpg").read_bytes()
    rgba, _ = harness.run(photo, ["fire"])
    here = cv2.cvtColor(
        cv2.imdecode(np.frombuffer(photo, np.uint8), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGBA
    )
    assert np.array_equal(rgba, here)
    # A half-transparent PNG does not: Python's decoding drops the alpha the browser keeps, so the
    # digests differ and the browser's own pixels come back, alpha and all.
    frame = np.zeros((120, 160, 4), np.uint8)
    frame[:, :, 1] = 200
    frame[:, :, 3] = 128
    ok, png = cv2.imencode(".png", frame)
    assert ok
    rgba, results = harness.run(png.tobytes(), ["fire"])
    assert rgba.shape == (120, 160, 4)
    assert (rgba[:, :, 3] == 128).all(), np.unique(rgba[:, :, 3])
    assert results["fire"]["boxes"] == []
    # Without pixels at all (the replay's way), the same results.
    assert harness.results(png.tobytes(), ["fire"]) == results


def test_matching_rule() -> None:
    a = [10, 10, 100, 100]
    assert parity.boxes_agree([a], [a])
    assert parity.boxes_agree([a, [300, 300, 50, 50]], [[300, 300, 50, 50], [11, 10, 100, 100]])
    assert not parity.boxes_agree([a], [])
    assert not parity.boxes_agree([a], [[30, 30, 100, 100]])  # IoU about 0.47
    # Two JS boxes may not both claim the same Python box.
    assert not parity.boxes_agree([a, [11, 11, 100, 100]], [a, [500, 500, 10, 10]])
    # Scored boxes (DNN) pair only with scores within 0.02.
    b = [300, 300, 50, 50]
    assert parity.boxes_agree([a, b], [b, a], [0.9, 0.6], [0.61, 0.89])
    assert not parity.boxes_agree([a, b], [b, a], [0.9, 0.6], [0.63, 0.89])
    assert not parity.boxes_agree([a], [a], [0.9], [])


def run_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", "parity", *args],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )


def test_cli_json_and_exit_status(tmp_path: Path) -> None:
    bad = tmp_path / "broken.jpg"
    bad.write_bytes(b"\xff\xd8 not really a jpeg")
    done = run_cli(str(FACES / "obama-480p.jpg"), str(bad), "--op", "face", "--json")
    assert done.returncode == 1, done.stderr
    result = json.loads(done.stdout)
    assert result["images"] == [str(FACES / "obama-480p.jpg")]
    # The full-frame scan, then the windowed search around the face it found.
    assert (result["pairs"], result["agree"], result["disagree"]) == (2, 2, 0)
    full, windowed = result["details"]
    assert full["js_boxes"] == full["py_boxes"] != [] and full["around"] is None
    assert windowed["js_boxes"] == windowed["py_boxes"] != []
    assert windowed["around"] in full["js_boxes"]
    assert "broken.jpg" in done.stderr


def test_cli_usage_errors() -> None:
    done = run_cli()
    assert done.returncode == 2 and "PATH" in done.stderr
    done = run_cli(str(FACES / "obama.jpg"), "--op", "dance")
    assert done.returncode == 2 and "'dance'" in done.stderr


def test_cli_text_output_lists_both_box_lists() -> None:
    done = run_cli(str(FACES / "two_people.jpg"), "--op", "face")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == f"{FACES / 'two_people.jpg'} face: agree"
    js, python = lines[1].split(), lines[2].split()
    assert js[0] == "js" and python[0] == "python" and js[1:] == python[1:] != ["[]"]
    assert lines[3].startswith(f"{FACES / 'two_people.jpg'} face (window around (")
    assert lines[3].endswith("): agree")
    # Told nothing, parity checks the relay's build.
    assert lines[-1] == f"1 images, 2 pairs (OpenCV.js {RELAY_OPENCV_BUILD}): 2 agree, 0 disagree"
