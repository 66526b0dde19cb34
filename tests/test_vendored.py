"""Every vendored file is the one its provenance names: app/static/VENDORED.json's sha256 of each
path matches the file in the repository (scripts/vendor.sh and scripts/build-opencv-js write
both)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_each_vendored_file_matches_its_recorded_sha256() -> None:
    vendored = json.loads((REPO / "app/static/VENDORED.json").read_text())
    assert vendored["files"]
    for entry in vendored["files"]:
        data = (REPO / entry["path"]).read_bytes()
        assert hashlib.sha256(data).hexdigest() == entry["sha256"], entry["path"]
        assert entry["package"], entry
