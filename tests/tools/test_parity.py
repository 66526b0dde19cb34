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

import pytest

from app.resources import OPERATIONS_SPEC
from app.server.config import Settings
from app.tools import parity
from app.vision.spec import load_spec
from tests.vision.frames import FACES, write_generated_frames

pytestmark = [pytest.mark.browser, pytest.mark.slow]

SPEC = load_spec(OPERATIONS_SPEC)
ALL_OPS = [o.id for o in SPEC.operations]


@pytest.fixture(scope="module")
def harness() -> Iterator[parity.Harness]:
    with parity.open_harness(Settings(environment="development", token=None)) as opened:
        yield opened


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
    assert len(report.details) == len(images) * len(ALL_OPS)
    # Parity of empty lists proves nothing: the photos must exercise the detectors.
    found = {op: sum(bool(p.js_boxes) for p in report.details if p.op == op) for op in ALL_OPS}
    assert found["face"] >= len(images) // 2, found


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


def test_thesis_profile_on_a_few_photos(harness: parity.Harness) -> None:
    report = parity.Report()
    for name in ("obama-480p.jpg", "two_people.jpg", "alex-lacamoire.png"):
        harness.check(FACES / name, ALL_OPS, report, profile="thesis")
    assert report.ok, describe(report)


def test_unreadable_image_is_reported_by_name(harness: parity.Harness, tmp_path: Path) -> None:
    bad = tmp_path / "not-a-picture.png"
    bad.write_bytes(b"this is text")
    report = parity.Report()
    harness.check(bad, ["face"], report)
    assert not report.ok
    assert "not-a-picture.png" in report.unreadable[str(bad)]


def test_matching_rule() -> None:
    a = [10, 10, 100, 100]
    assert parity.boxes_agree([a], [a])
    assert parity.boxes_agree([a, [300, 300, 50, 50]], [[300, 300, 50, 50], [11, 10, 100, 100]])
    assert not parity.boxes_agree([a], [])
    assert not parity.boxes_agree([a], [[30, 30, 100, 100]])  # IoU about 0.47
    # Two JS boxes may not both claim the same Python box.
    assert not parity.boxes_agree([a, [11, 11, 100, 100]], [a, [500, 500, 10, 10]])


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
    assert (result["pairs"], result["agree"], result["disagree"]) == (1, 1, 0)
    assert result["details"][0]["js_boxes"] == result["details"][0]["py_boxes"] != []
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
    assert lines[-1] == "1 images, 1 pairs: 1 agree, 0 disagree"
