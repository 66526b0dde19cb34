"""``autopilot bench --camera``'s measurement on a few frames: both scenes timed, the billboards
in the arena's frames, the report written."""

from __future__ import annotations

import json
from pathlib import Path

from app.tools.bench import camera


def test_a_short_camera_run_times_both_scenes_and_writes_its_report(tmp_path: Path) -> None:
    obj = camera.run(tmp_path, frames=6, fps=30.0)
    assert obj["size"] == [640, 480] and obj["frames"] == 6
    for scene in ("arena", "empty_arena"):
        assert obj[scene]["render_ms"]["p50"] > 0
        assert obj[scene]["encode_ms"]["p50"] > 0
    # The walker's face fills much of every frame: its detail makes the JPEGs larger than the
    # bare walls'.
    assert obj["arena"]["jpeg_bytes"]["p50"] > 1.2 * obj["empty_arena"]["jpeg_bytes"]["p50"]
    assert json.loads((tmp_path / "camera.json").read_text()) == obj
    report = (tmp_path / "camera.md").read_text()
    assert "| the arena |" in report and "| empty arena (baseline) |" in report
