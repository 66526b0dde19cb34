"""The OpenCV.js builds bench's pure core: the relay's per-snapshot cost, the figures, the
choice of build and the report (``autopilot bench --opencv-builds``)."""

from __future__ import annotations

from typing import Any

import pytest

from app.cli import main
from app.protocol.opencv import RELAY_OPENCV_BUILD
from app.tools.bench.opencv_builds import (
    FrameTimes,
    OpTimes,
    agrees_with_python,
    choose,
    decide,
    op_figures,
    report_text,
    tracking_ops,
    verdict,
)
from app.vision.reference import Detection


def frame(
    simd: float,
    official: float,
    window: tuple[float, float] | None = None,
    agrees: tuple[bool, bool] = (True, True),
) -> FrameTimes:
    return FrameTimes(
        full_ms={"simd": simd, "official": official},
        window_ms={
            "simd": None if window is None else window[0],
            "official": None if window is None else window[1],
        },
        python_ms=10.0,
        agrees={"simd": agrees[0], "official": agrees[1]},
    )


def test_the_relay_scans_in_full_once_in_full_scan_every_snapshots() -> None:
    tracked = frame(30.0, 40.0, window=(3.0, 4.0))
    # One full scan and 29 window searches per 30 snapshots.
    assert tracked.relay_ms("simd", 30) == (30.0 + 29 * 3.0) / 30
    assert tracked.relay_ms("official", 30) == (40.0 + 29 * 4.0) / 30
    # Nothing to follow: every snapshot is a full scan.
    assert frame(30.0, 40.0).relay_ms("simd", 30) == 30.0
    # Tracking off (thesis profile): every snapshot is a full scan.
    assert tracked.relay_ms("simd", 1) == 30.0


def test_figures_pair_frames_and_take_the_median_ratio() -> None:
    times = OpTimes(
        "face",
        30,
        [
            frame(20.0, 40.0, window=(2.0, 2.0)),
            frame(30.0, 40.0, window=(3.0, 2.0), agrees=(False, True)),
            frame(40.0, 40.0),  # found nothing: no window search
        ],
    )
    found = op_figures(times)
    assert found["frames"] == 3 and found["full_scan_every"] == 30
    assert found["agrees"] == {"simd": 2, "official": 3}
    assert found["full"] == {
        "simd": 30.0,
        "official": 40.0,
        "frames": 3,
        "ratio": 0.75,
        "ratio_q1": 0.625,
        "ratio_q3": 0.875,
        "python": 10.0,
    }
    # Only the two frames where both builds searched a window.
    assert found["window"]["frames"] == 2
    assert found["window"]["ratio"] == 1.25
    relay = [f.relay_ms("simd", 30) / f.relay_ms("official", 30) for f in times.frames]
    assert found["relay"]["ratio"] == round(sorted(relay)[1], 3)


def figures(
    op: str, ratio: float, q3: float, agrees: tuple[int, int] = (40, 40), q1: float | None = None
) -> dict[str, Any]:
    return {
        "op": op,
        "frames": 40,
        "agrees": {"simd": agrees[0], "official": agrees[1]},
        "relay": {"ratio": ratio, "ratio_q1": ratio if q1 is None else q1, "ratio_q3": q3},
    }


def test_a_build_is_better_for_an_operation_by_a_tenth_on_three_frames_in_four() -> None:
    assert verdict(figures("face_dnn", 0.9, 0.99))[0] == "simd"
    assert verdict(figures("face", 0.91, 0.95))[0] == "level"
    assert verdict(figures("face", 0.8, 1.0))[0] == "level"  # slower on a quarter of the frames
    # The official build, symmetrically: SIMD takes at least 1 / 0.9 of its time.
    assert verdict(figures("face", 1.12, 1.3, q1=1.01))[0] == "official"
    assert verdict(figures("face", 1.1, 1.3, q1=1.01))[0] == "level"
    assert verdict(figures("face", 1.2, 1.3, q1=1.0))[0] == "level"
    # Right less often is worse, however fast.
    build, reason = verdict(figures("face", 0.5, 0.6, agrees=(39, 40)))
    assert build == "official" and "39 of 40" in reason
    # Both wrong on the same frame is no reason against SIMD.
    assert verdict(figures("face", 0.5, 0.6, agrees=(39, 39)))[0] == "simd"


def test_the_relay_loads_simd_when_it_is_better_for_some_operation_and_worse_for_none() -> None:
    build, reason = choose([figures("face", 0.95, 1.06), figures("face_dnn", 0.2, 0.3)])
    assert build == "simd"
    assert "faster on face_dnn 0.2" in reason and "level on face 0.95" in reason
    build, reason = choose([figures("face", 1.2, 1.3, q1=1.1), figures("face_dnn", 0.2, 0.3)])
    assert build == "official" and "worse on face 1.2" in reason
    build, reason = choose([figures("face", 0.95, 1.06), figures("body", 0.93, 1.05)])
    assert build == "official" and "no speed-up" in reason and "face 0.95" in reason


def test_nothing_measured_keeps_the_official_build() -> None:
    assert choose([]) == ("official", "nothing was measured")
    assert choose([figures("face", None, None)])[0] == "official"  # type: ignore[arg-type]


def run(ops: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "command": "autopilot bench --opencv-builds",
        "started": "then",
        "machine": "here",
        "chromium": "1",
        "load_average": [1.0, 2.0],
        "frames": 2,
        "repeats": 3,
        "ops": ops,
    }


def test_the_report_shows_each_scan_the_choice_and_what_the_relay_loads() -> None:
    times = OpTimes("face", 30, [frame(20.0, 40.0, window=(2.0, 4.0))] * 2)
    found = decide(run([op_figures(times)]))
    assert found["relay_loads"] == RELAY_OPENCV_BUILD
    assert found["choice"] == "simd"
    text = report_text(found)
    assert "| face | full | 2 | 20.0 | 40.0 | 0.5 | 0.5 | 10.0 |" in text
    assert "| face | window | 2 | 2.0 | 4.0 | 0.5 | 0.5 |  |" in text
    assert "the fastest of 3 run(s) each" in text
    assert "**Measured choice: simd**" in text
    assert (
        "The better build per operation (median ≤ 0.9 and faster on three frames in four):"
        " face simd." in text
    )
    mismatch = "not the one measured here"
    assert (mismatch in text) == (RELAY_OPENCV_BUILD != "simd")
    slower = decide(run([op_figures(OpTimes("face", 30, [frame(40.0, 40.0)] * 2))]))
    assert slower["choice"] == "official"
    assert (mismatch in report_text(slower)) == (RELAY_OPENCV_BUILD != "official")


def test_a_dnn_scan_agrees_with_python_as_parity_judges_it_a_cascade_box_for_box() -> None:
    scored = Detection([(100, 100, 50, 50)], (125.0, 125.0), scores=(0.9,))
    # One pixel off is IoU 0.92 with the score within 0.02: the DNN's parity holds.
    assert agrees_with_python([(101, 100, 50, 50)], [0.91], scored)
    assert not agrees_with_python([(101, 100, 50, 50)], [0.93], scored)
    assert not agrees_with_python([(110, 100, 50, 50)], [0.9], scored)
    assert not agrees_with_python([], [], scored)
    # A cascade's boxes are Python's exactly, in any order.
    cascade = Detection([(1, 2, 3, 4), (5, 6, 7, 8)], (2.5, 4.0))
    assert agrees_with_python([(5, 6, 7, 8), (1, 2, 3, 4)], [], cascade)
    assert not agrees_with_python([(1, 2, 3, 4), (5, 6, 7, 9)], [], cascade)


def test_warmup_and_repeats_go_with_the_builds_bench_only(caplog: pytest.LogCaptureFixture) -> None:
    # --warmup shortens the builds bench's uncounted frames; on another bench it means nothing
    # and must not start that bench with it ignored.
    assert main(["bench", "--recorder", "--warmup", "0"]) == 2
    assert "--warmup goes with --opencv-builds" in caplog.text
    assert main(["bench", "--recorder", "--repeats", "1"]) == 2
    assert "--repeats goes with --opencv-builds" in caplog.text
    with pytest.raises(SystemExit):
        main(["bench", "--opencv-builds", "--warmup", "-1"])


def test_the_builds_bench_measures_operations_that_track(caplog: pytest.LogCaptureFixture) -> None:
    assert main(["bench", "--opencv-builds", "--ops", "face,fire"]) == 2
    assert "fire is not one that tracks (face, face_small, face_dnn, body)" in caplog.text
    assert tracking_ops() == ["face", "face_small", "face_dnn", "body"]
