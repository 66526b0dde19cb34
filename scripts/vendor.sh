#!/usr/bin/env bash
# Re-fetch the vendored browser libraries from the npm registry with `npm pack`, copy them into
# app/static, and record package, version and sha256 in app/static/VENDORED.json.
# The pins live here on purpose: OpenCV.js must stay on 4.12 to match opencv-python-headless
# (OpenCV 5 has no CascadeClassifier), and roslib 1.x ships a self-contained browser build.
set -euo pipefail
cd "$(dirname "$0")/.."

OPENCV_PKG="@techstark/opencv-js@4.12.0-release.1"
ROSLIB_PKG="roslib@1.4.1"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

fetch() { # fetch PKG FILE_IN_PACKAGE DEST
    local pkg=$1 inner=$2 dest=$3 tgz
    tgz=$(cd "$work" && npm pack --silent "$pkg" | tail -n 1)
    mkdir -p "$work/x" && rm -rf "$work/x/package"
    tar -xzf "$work/$tgz" -C "$work/x"
    install -D -m 0644 "$work/x/package/$inner" "$dest"
    printf '    {"package": "%s", "file": "%s", "path": "%s", "sha256": "%s"}' \
        "$pkg" "$inner" "$dest" "$(sha256sum "$dest" | cut -d' ' -f1)"
}

{
    echo '{"source": "npm registry via scripts/vendor.sh", "files": ['
    fetch "$OPENCV_PKG" dist/opencv.js app/static/opencv.js
    echo ','
    fetch "$ROSLIB_PKG" build/roslib.min.js app/static/vendor/roslib.min.js
    echo
    echo ']}'
} > app/static/VENDORED.json.tmp
# Keep the entries this script does not fetch (the SIMD build of scripts/build-opencv-js).
python3 - <<'PY'
import json
from pathlib import Path

old, new = Path("app/static/VENDORED.json"), Path("app/static/VENDORED.json.tmp")
fetched = json.loads(new.read_text())
paths = {entry["path"] for entry in fetched["files"]}
kept = [e for e in json.loads(old.read_text())["files"] if e["path"] not in paths] if old.exists() else []
lines = [json.dumps(entry) for entry in fetched["files"] + kept]
new.write_text('{"source": ' + json.dumps(fetched["source"]) + ', "files": [\n    ' + ",\n    ".join(lines) + "\n]}\n")
PY
mv app/static/VENDORED.json.tmp app/static/VENDORED.json
cat app/static/VENDORED.json
