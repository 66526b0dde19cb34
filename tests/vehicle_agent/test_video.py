"""Video sources: the synthetic scene (face where it says, frame tag readable) and files."""

from __future__ import annotations

import fractions
import math
from pathlib import Path

import av
import cv2
import numpy as np
import pytest

from app.protocol import frametag
from app.protocol.events import FrameSent
from app.resources import OPERATIONS_SPEC
from app.vision.reference import detect
from app.vision.spec import load_spec
from vehicle_agent.video import (
    FileVideo,
    FixedPath,
    SweepPath,
    SyntheticVideo,
    VideoSourceError,
    open_source,
)

CASCADE = cv2.CascadeClassifier(
    str(Path(cv2.data.haarcascades) / "haarcascade_frontalface_default.xml")
)


def detect_faces(rgb: np.ndarray) -> list[tuple[int, int, int, int]]:
    gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    found = CASCADE.detectMultiScale(gray, scaleFactor=1.1, minNeighbors=5, minSize=(30, 30))
    return [tuple(int(v) for v in f) for f in found]


def test_synthetic_face_is_found_by_the_cascade_where_the_source_says() -> None:
    video = SyntheticVideo(640, 480, fps=15)
    try:
        for frame in (0, 60, 75, 90, 150, 170):  # left hold, glide, right hold, glide back
            rgb = video.render(frame)
            assert frametag.read(rgb) == frame
            faces = detect_faces(rgb)
            assert len(faces) == 1, f"frame {frame}: {faces}"
            x, y, w, h = faces[0]
            cx, cy = video.face_centre(frame)
            # The cascade's box is centred on the true position within a tenth of the face.
            assert abs(x + w / 2 - cx) < 0.1 * w and abs(y + h / 2 - cy) < 0.1 * h
    finally:
        video.stop()


def test_sweep_path_visits_both_sides() -> None:
    path = SweepPath()
    assert path(1.0)[0] < 0.3 and path(7.0)[0] > 0.7 and path(13.0)[0] < 0.3
    assert path(5.0)[0] == pytest.approx(0.5)  # halfway through the glide


def test_sweep_path_leaps_across_the_frame_at_its_jump_times() -> None:
    path = SweepPath()
    leap_right, leap_left = path.jump_times()
    dt = 1e-3
    for cycle in range(3):
        base = cycle * path.cycle_s
        for at, before, after in (
            (leap_right, path.left, path.right),
            (leap_left, path.right, path.left),
        ):
            t = base + at
            assert path(t - dt)[0] == pytest.approx(before)
            assert path(t)[0] == pytest.approx(after)
            assert path.jumped(t - dt, t)
    # The glides are not leaps, nor is the start of the path.
    assert not path.jumped(0.0, leap_right - dt)
    assert not path.jumped(-1.0, 0.0)


def test_a_shorter_sweep_keeps_the_shape_and_any_window_of_one_cycle_holds_both_leaps() -> None:
    # `--sweep-s` (and `bench --seconds`): the same glides and leaps, played faster.
    default, fast = SweepPath(), SweepPath.with_cycle(8.0)
    assert SweepPath.with_cycle(default.cycle_s) == default
    assert fast.cycle_s == pytest.approx(8.0)
    for t in (0.5, 2.0, 4.0, 6.0, 7.0, 7.9):
        assert fast(t) == pytest.approx(default(t * default.cycle_s / 8.0))
    leaps = [k * fast.cycle_s + at for k in range(4) for at in fast.jump_times()]
    for start in (0.1, 3.3, 5.0, 9.7):
        end = start + fast.cycle_s
        assert fast.jumped(start, end)
        assert len([t for t in leaps if start < t <= end]) == 2


def test_synthetic_frames_flag_exactly_the_jumps() -> None:
    fps = 30.0
    infos: list[FrameSent] = []
    video = SyntheticVideo(320, 240, fps=fps, on_frame=infos.append)
    path = video.path
    assert isinstance(path, SweepPath)
    try:
        frames = range(round(2 * path.cycle_s * fps) + 2)
        jumps = [f for f in frames if video.jumped(f)]
        # Two leaps per cycle, each flagged on one frame only: the first that shows it.
        assert len(jumps) == 4
        for f in jumps:
            (x0, _), (x1, _) = video.face_centre(f - 1), video.face_centre(f)
            assert abs(x1 - x0) > 0.5 * 320
        steps = [abs(video.face_centre(f)[0] - video.face_centre(f - 1)[0]) for f in frames[1:]]
        assert max(s for f, s in zip(frames[1:], steps, strict=True) if f not in jumps) < 10
    finally:
        video.stop()


def test_the_scene_has_a_flame_apart_from_the_face() -> None:
    """Face and fire operations pick different targets in the same frames."""
    spec = load_spec(OPERATIONS_SPEC)
    video = SyntheticVideo(640, 480, fps=30)
    try:
        flame = video.flame_centre()
        assert flame is not None
        for frame in (0, 150, 300, 479, 480, 530):
            rgba = cv2.cvtColor(video.render(frame), cv2.COLOR_RGB2RGBA)
            fire = detect(spec.op("fire"), rgba)
            face = detect(spec.op("face"), rgba)
            assert fire.target is not None and face.target is not None, frame
            # Each target lies within a few pixels of the thing it should find ...
            assert math.dist(fire.target, flame) < 6, (frame, fire.target, flame)
            assert math.dist(face.target, video.face_centre(frame)) < 6, frame
            # ... and the two are far apart: switching operation moves the target.
            assert math.dist(fire.target, face.target) > 150
    finally:
        video.stop()


def test_a_scene_without_a_flame_gives_the_fire_operation_nothing() -> None:
    spec = load_spec(OPERATIONS_SPEC)
    video = SyntheticVideo(640, 480, fps=30, flame=None)
    try:
        rgba = cv2.cvtColor(video.render(0), cv2.COLOR_RGB2RGBA)
        assert detect(spec.op("fire"), rgba).target is None
    finally:
        video.stop()


async def test_synthetic_track_paces_tags_and_reports_frames() -> None:
    infos: list[FrameSent] = []
    video = SyntheticVideo(320, 240, fps=50, path=FixedPath(0.3, 0.5), on_frame=infos.append)
    try:
        frames = [await video.recv() for _ in range(10)]
    finally:
        video.stop()
    tags = [frametag.read(f.to_ndarray(format="rgb24")) for f in frames]
    assert tags == list(range(10))
    assert [f.pts for f in frames] == [round(i * 90_000 / 50) for i in range(10)]
    assert frames[0].time_base == fractions.Fraction(1, 90_000)
    assert [i.frame for i in infos] == list(range(10))
    assert infos[0].face_x == pytest.approx(0.3 * 320)
    # 9 frame periods at 50 fps take about 180 ms.
    assert infos[-1].t - infos[0].t == pytest.approx(0.18, abs=0.1)


def write_tagged_clip(path: Path, codec: str, frames: int, size: tuple[int, int]) -> None:
    """A short clip whose frames carry their own numbers as tags."""
    video = SyntheticVideo(*size, fps=25, path=FixedPath(0.5, 0.5))
    with av.open(str(path), "w") as out:
        stream = out.add_stream(codec, rate=25)
        stream.width, stream.height = size
        stream.pix_fmt = "yuv420p"
        if codec == "mpeg4":
            stream.options = {"qscale": "2"}
        for i in range(frames):
            frame = av.VideoFrame.from_ndarray(video.render(i), format="rgb24")
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    video.stop()


@pytest.mark.parametrize(("suffix", "codec"), [(".y4m", "rawvideo"), (".mp4", "mpeg4")])
async def test_file_source_loops(tmp_path: Path, suffix: str, codec: str) -> None:
    clip = tmp_path / f"clip{suffix}"
    write_tagged_clip(clip, codec, frames=5, size=(320, 240))
    track = open_source(str(clip), fps=200)
    try:
        frames = [await track.recv() for _ in range(12)]
    finally:
        track.stop()
    tags = [frametag.read(f.to_ndarray(format="rgb24")) for f in frames]
    assert tags == [0, 1, 2, 3, 4, 0, 1, 2, 3, 4, 0, 1]


async def test_file_source_rescales(tmp_path: Path) -> None:
    clip = tmp_path / "clip.y4m"
    write_tagged_clip(clip, "rawvideo", frames=2, size=(320, 240))
    track = FileVideo(clip, size=(160, 120), fps=100)
    try:
        frame = await track.recv()
    finally:
        track.stop()
    assert (frame.width, frame.height) == (160, 120)


def test_bad_sources_name_the_problem(tmp_path: Path) -> None:
    with pytest.raises(VideoSourceError, match="no such video file: .*missing.mp4"):
        open_source(str(tmp_path / "missing.mp4"))
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"this is not a video")
    with pytest.raises(VideoSourceError, match="junk.mp4"):
        open_source(str(junk))
    with pytest.raises(VideoSourceError, match="no such video device: /dev/video99"):
        open_source("/dev/video99")
