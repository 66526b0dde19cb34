"""``autopilot bench --opencv-builds`` as a user runs it, on one frame timed once and no
warm-up: both builds and Python timed on a cascade and the DNN face, the report written, and the
exit status saying whether the build the relay loads is the measured choice (which build wins is
the report's business, never asserted). The figures' arithmetic, the choice and the report's text
are checked against hand-made runs in test_opencv_builds.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from app.protocol.opencv import OPENCV_BUILDS, RELAY_OPENCV_BUILD

pytestmark = [
    pytest.mark.bench,
    pytest.mark.slow,
    pytest.mark.browser,
    pytest.mark.timeout(200),
    pytest.mark.xdist_group("benches"),  # the shorter benches' lane (test_field_quick.py)
]


def test_the_builds_bench_times_each_build_and_writes_its_report(tmp_path: Path) -> None:
    argv = [sys.executable, "-m", "app.cli", "bench", "--opencv-builds", "--json"]
    argv += ["--ops", "face,face_dnn", "--frames", "1", "--warmup", "0", "--repeats", "1"]
    argv += ["--out", str(tmp_path)]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=180)
    assert done.stdout, done.stderr[-3000:]
    found = json.loads(done.stdout.splitlines()[-1])
    assert found["relay_loads"] == RELAY_OPENCV_BUILD
    assert found["choice"] in OPENCV_BUILDS
    assert "--ops face,face_dnn --frames 1 --warmup 0 --repeats 1" in found["command"]
    assert found["repeats"] == 1
    # 1 when the measurement chooses another build than the relay loads.
    assert done.returncode == (0 if found["choice"] == RELAY_OPENCV_BUILD else 1), done.stderr
    assert [op["op"] for op in found["ops"]] == ["face", "face_dnn"]
    for op in found["ops"]:
        assert op["frames"] == 1 and op["full_scan_every"] > 1, op
        # Both builds ran the same detection as Python on the synthetic face (the DNN's boxes
        # and scores as parity judges them).
        assert op["agrees"] == dict.fromkeys(OPENCV_BUILDS, 1), op
        for scan in ("full", "relay"):
            assert all(op[scan][build] > 0 for build in OPENCV_BUILDS), op
            assert op[scan]["ratio"] > 0, op
        assert op["full"]["python"] > 0, op
    # The face is found, so the relay's work there is mostly window searches.
    for op in found["ops"]:
        assert op["window"]["frames"] == 1, op
        assert op["relay"]["official"] < op["full"]["official"], op
    report = (tmp_path / "opencv-builds.md").read_text()
    assert (
        "| face_dnn | relay | 1 |" in report and f"**Measured choice: {found['choice']}**" in report
    )
    assert json.loads((tmp_path / "opencv-builds.json").read_text()) == found
