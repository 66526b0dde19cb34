"""Every vendored file is the one its provenance names, and OpenCV is one version everywhere.

app/static/VENDORED.json (written by scripts/vendor alone) records each vendored file's package,
version and sha256; the files in the repository must match it, and it must match the pins in
pyproject.toml. OpenCV is pinned once, by the opencv-python-headless dependency: the places that
cannot read that pin (constraints.txt, written from what was installed; the record itself) are
checked against it here.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
STATIC = REPO / "app/static"
FIELDS = {"path", "package", "version", "source", "file", "sha256"}


def vendored() -> dict[str, Any]:
    document: dict[str, Any] = json.loads((STATIC / "VENDORED.json").read_text())
    return document


def pyproject() -> dict[str, Any]:
    with (REPO / "pyproject.toml").open("rb") as file:
        return tomllib.load(file)


def opencv_pin() -> str:
    pins = [
        match.group(1)
        for requirement in pyproject()["project"]["dependencies"]
        if (match := re.fullmatch(r"opencv-python-headless==([0-9.]+)", requirement))
    ]
    assert len(pins) == 1, pins
    return pins[0]


def test_each_vendored_file_matches_its_recorded_sha256() -> None:
    document = vendored()
    assert document["written_by"] == "scripts/vendor"
    assert document["files"]
    for entry in document["files"]:
        assert FIELDS <= set(entry) and all(entry[key] for key in FIELDS), entry
        data = (REPO / entry["path"]).read_bytes()
        assert hashlib.sha256(data).hexdigest() == entry["sha256"], entry["path"]


def test_every_vendored_file_is_recorded() -> None:
    on_disk = {
        str(path.relative_to(REPO))
        for path in [*STATIC.glob("opencv*.js"), *(STATIC / "vendor").iterdir()]
    }
    files = vendored()["files"]
    licences = {entry["licence_file"] for entry in files if "licence_file" in entry}
    assert on_disk == {entry["path"] for entry in files} | licences


def test_the_face_model_is_blazeface_short_range_with_its_licence() -> None:
    """The face_dnn operation's model is the one the npm package ships, byte for byte, and the
    Apache-2.0 text it is distributed under is beside it."""
    (entry,) = [e for e in vendored()["files"] if e["path"].endswith(".tflite")]
    assert entry["path"] == "app/static/vendor/face_detection_short_range.tflite"
    assert entry["package"] == "@mediapipe/face_detection"
    assert entry["file"] == "face_detection_short_range.tflite"
    model = (REPO / entry["path"]).read_bytes()
    assert (
        hashlib.sha256(model).hexdigest()
        == "3bc182eb9f33925d9e58b5c8d59308a760f4adea8f282370e428c51212c26633"
    )
    assert entry["licence"] == "Apache-2.0"
    text = (REPO / entry["licence_file"]).read_text()
    assert "Apache License" in text and "Version 2.0, January 2004" in text


def test_the_record_holds_the_npm_packages_pyproject_pins() -> None:
    opencv = ".".join(opencv_pin().split(".")[:3])
    pins = pyproject()["tool"]["autopilot"]["vendor"]["npm"]
    by_path = {entry["path"]: entry for entry in vendored()["files"]}
    for path, pin in pins.items():
        entry = by_path[path]
        assert entry["package"] == pin["package"] and entry["file"] == pin["file"], entry
        assert entry["version"] == pin["version"].format(opencv=opencv), entry
    # The official OpenCV.js is the pinned OpenCV's build.
    assert by_path["app/static/opencv.js"]["version"].startswith(f"{opencv}-")


def test_opencv_is_one_version_on_both_sides() -> None:
    pin = opencv_pin()
    built = [e for e in vendored()["files"] if e["package"] == "opencv-python-headless"]
    assert [e["path"] for e in built] == ["app/static/opencv-simd.js"]
    assert built[0]["version"] == pin
    sdist_sha256 = pyproject()["tool"]["autopilot"]["vendor"]["opencv-sdist-sha256"]
    assert sdist_sha256 in built[0]["source"]
    constraints = (REPO / "constraints.txt").read_text().splitlines()
    assert f"opencv-python-headless=={pin}" in constraints


def test_the_simd_build_records_each_patch_build_opencv_js_applies() -> None:
    """scripts/build-opencv-js applies every scripts/opencv-js-patches/*.patch; a patch changed
    or added without a rebuild (and its record) fails here."""
    (entry,) = [e for e in vendored()["files"] if e["path"] == "app/static/opencv-simd.js"]
    patches = sorted((REPO / "scripts/opencv-js-patches").glob("*.patch"))
    assert patches
    assert [p["path"] for p in entry["patches"]] == [str(p.relative_to(REPO)) for p in patches]
    for recorded, patch in zip(entry["patches"], patches, strict=True):
        assert hashlib.sha256(patch.read_bytes()).hexdigest() == recorded["sha256"]


def test_record_simd_writes_the_builds_provenance_and_keeps_the_rest(tmp_path: Path) -> None:
    """`scripts/vendor record-simd`, as scripts/build-opencv-js calls it, in a copy of the
    repository's pins and record: the built file's sha256, the sdist it came from and each
    patch with its sha256; the npm entries left as they were."""
    (tmp_path / "scripts/opencv-js-patches").mkdir(parents=True)
    (tmp_path / "app/static").mkdir(parents=True)
    shutil.copy(REPO / "scripts/vendor", tmp_path / "scripts/vendor")
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    shutil.copy(STATIC / "VENDORED.json", tmp_path / "app/static/VENDORED.json")
    (tmp_path / "app/static/opencv-simd.js").write_bytes(b"built")
    patch = tmp_path / "scripts/opencv-js-patches/a.patch"
    patch.write_bytes(b"--- a\n+++ b\n")
    argv = [sys.executable, "scripts/vendor", "record-simd", "app/static/opencv-simd.js", "emcc 9"]
    argv.append("scripts/opencv-js-patches/a.patch")
    done = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    written = json.loads((tmp_path / "app/static/VENDORED.json").read_text())
    assert written["written_by"] == "scripts/vendor"
    by_path = {entry["path"]: entry for entry in written["files"]}
    simd = by_path.pop("app/static/opencv-simd.js")
    assert simd["sha256"] == hashlib.sha256(b"built").hexdigest()
    assert simd["package"] == "opencv-python-headless" and simd["version"] == opencv_pin()
    assert pyproject()["tool"]["autopilot"]["vendor"]["opencv-sdist-sha256"] in simd["source"]
    assert simd["toolchain"] == "emcc 9"
    assert simd["patches"] == [
        {
            "path": "scripts/opencv-js-patches/a.patch",
            "sha256": hashlib.sha256(b"--- a\n+++ b\n").hexdigest(),
        }
    ]
    kept = {e["path"]: e for e in vendored()["files"] if e["path"] != "app/static/opencv-simd.js"}
    assert by_path == kept
