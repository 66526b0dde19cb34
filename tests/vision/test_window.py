"""Detect, then track (app/vision/window.py) with the Python reference on the synthetic scene."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from app.resources import OPERATIONS_SPEC
from app.vision import reference, spec, window
from vehicle_agent.video import FixedPath, SyntheticVideo

SPEC = spec.load_spec(OPERATIONS_SPEC)
FACE = SPEC.op("face")
assert isinstance(FACE, spec.CascadeOperation)
EVERY = FACE.params.full_scan_every


def scene(path: FixedPath) -> tuple[SyntheticVideo, FixedPath]:
    return SyntheticVideo(path=path), path


def rgba(video: SyntheticVideo, frame: int) -> npt.NDArray[np.uint8]:
    return cv2.cvtColor(video.render(frame), cv2.COLOR_RGB2RGBA)


def contains(box: window.Box | None, point: tuple[float, float]) -> bool:
    assert box is not None
    x, y, w, h = box
    return x <= point[0] <= x + w and y <= point[1] <= y + h


def test_the_window_grows_the_box_and_stays_in_the_image() -> None:
    # A 40-pixel box at (100, 100) of the full frame, detection image at half size.
    assert window.search_region((100, 100, 40, 40), 2.0, 320, 240, 0.5) == (40, 40, 40, 40)
    # Near a corner the window is clipped to the detection image.
    assert window.search_region((0, 0, 40, 40), 2.0, 320, 240, 0.5) == (0, 0, 30, 30)
    # A box wholly outside the image leaves nothing to search.
    assert window.search_region((700, 500, 40, 40), 2.0, 320, 240, 0.5) is None


def test_the_window_looks_for_sizes_near_the_last_target() -> None:
    # A 60x40 box of the full frame at half size: 20 / 1.5 = 13.3 and 30 * 1.5 = 45 pixels.
    assert window.search_sizes((0, 0, 60, 40), 2.0, 1.5, (0, 0), (0, 0)) == ((13, 13), (45, 45))
    # The operation's own limits still hold, the larger of the minimums and smaller of maximums.
    assert window.search_sizes((0, 0, 60, 40), 2.0, 1.5, (24, 20), (40, 50)) == ((24, 20), (40, 45))


def test_a_face_much_smaller_than_the_last_target_is_left_to_the_full_scan() -> None:
    video, _ = scene(FixedPath(0.3, 0.42))
    frame = rgba(video, 0)
    (face,) = reference.detect(FACE, frame).boxes
    x, y, w, h = face
    # A last target three times the face's size, centred on it: the window covers the face,
    # but looks only for sizes from 3 / ratio of the face's up.
    thrice = (x - w, y - h, 3 * w, 3 * h)
    assert FACE.params.window_size_ratio < 2
    assert reference.detect(FACE, frame, around=thrice).boxes == []
    tracker = window.Tracker(EVERY)
    tracker.record(thrice, "full")
    found, scan = window.step(tracker, lambda around: reference.detect(FACE, frame, around=around))
    assert scan == "full" and found.boxes == [face]


def test_the_size_range_keeps_the_box_a_search_of_every_size_finds() -> None:
    # The ratio is only there to skip work: on the moving face of the synthetic scene, the
    # window finds the very box it would find looking for every size (too small a ratio drops
    # raw hits that the grouping averages into the box, and moves it by a few pixels).
    video = SyntheticVideo()
    every_size = FACE.model_copy(
        update={"params": FACE.params.model_copy(update={"window_size_ratio": 1e6})}
    )
    for i in range(0, 1200, 20):
        frame = rgba(video, i)
        (face,) = reference.detect(FACE, frame).boxes
        windowed = reference.detect(FACE, frame, around=face)
        assert windowed.boxes == reference.detect(every_size, frame, around=face).boxes, i


@pytest.mark.parametrize(("dx", "dy"), [(1, 0), (-1, 0), (0, 1), (0, -1)])
def test_the_window_follows_a_walking_face_and_no_faster_one(dx: int, dy: int) -> None:
    # The margin is how far a target may move between two snapshots and stay in the window. A
    # person crossing the picture at walking pace moves about 0.3 of a face width per snapshot
    # at 30 frames/s (docs/bench/relay-cost.md): a move of 0.35 of the face's size (that, and
    # the few pixels a detected box wanders) is searched in the window and found where the face
    # now is. The window is no larger than that: a move of 0.45 (half as fast again) is left to
    # the full scan, which finds the face on the same snapshot, and so is a move of its size.
    video, path = scene(FixedPath(0.45, 0.42))
    (face,) = reference.detect(FACE, rgba(video, 0)).boxes
    for share, expected in ((0.35, "window"), (0.45, "full"), (1.0, "full")):
        path.x = 0.45 + dx * share * face[2] / video.width
        path.y = 0.42 + dy * share * face[3] / video.height
        frame = rgba(video, 0)
        tracker = window.Tracker(EVERY)
        tracker.record(face, "full")
        found, scan = window.step(
            tracker, lambda around, frame=frame: reference.detect(FACE, frame, around=around)
        )
        assert scan == expected, (share, found)
        assert contains(window.largest(found.boxes), video.face_centre(0)), (share, found)


@pytest.mark.parametrize(
    ("width", "height", "detect_width"),
    [(640, 480, 256), (1280, 720, 256), (800, 600, 256), (1920, 1080, 256), (320, 240, 256)],
)
def test_reducing_the_window_part_alone_gives_the_pixels_of_the_whole_reduction(
    width: int, height: int, detect_width: int
) -> None:
    # The window search converts and reduces only its part of the frame: for that to change
    # nothing, the part reduced on the grid must equal the same pixels of the whole frame reduced.
    rng = np.random.default_rng(5)
    frame = cv2.resize(SyntheticVideo().render(7), (width, height))
    noisy = np.clip(frame + rng.integers(-30, 30, frame.shape), 0, 255).astype(np.uint8)
    gray = cv2.cvtColor(noisy, cv2.COLOR_RGB2GRAY)
    size = (detect_width, int(height * detect_width / width + 0.5))
    whole = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
    for _ in range(200):
        x0, y0 = int(rng.integers(0, size[0] - 1)), int(rng.integers(0, size[1] - 1))
        x1, y1 = int(rng.integers(x0 + 1, size[0] + 1)), int(rng.integers(y0 + 1, size[1] + 1))
        region = (x0, y0, x1 - x0, y1 - y0)
        rects = window.source_rect(region, width, height, size)
        assert rects is not None
        (gx, gy, gw, gh), source = rects
        assert gx <= x0 and gy <= y0 and gx + gw >= x1 and gy + gh >= y1
        part = cv2.resize(window.crop(gray, source), (gw, gh), interpolation=cv2.INTER_AREA)
        assert np.array_equal(
            window.crop(part, (x0 - gx, y0 - gy, x1 - x0, y1 - y0)), window.crop(whole, region)
        ), region


def test_a_grid_that_is_not_exact_in_doubles_reduces_the_whole_frame() -> None:
    # 640 → 480 is a scale of 4/3: its weights are not exact in doubles, so no part is reduced
    # alone; 640 → 256 (5/2) repeats every 2 detection pixels, i.e. every 5 frame pixels.
    assert window.source_rect((10, 10, 50, 40), 640, 480, (480, 360)) is None
    assert window.source_rect((11, 11, 50, 40), 640, 480, (256, 192)) == (
        (10, 10, 52, 42),
        (25, 25, 130, 105),
    )


def test_the_windowed_search_finds_the_face_the_full_scan_found() -> None:
    video, _ = scene(FixedPath(0.3, 0.42))
    frame = rgba(video, 0)
    full = reference.detect(FACE, frame)
    assert len(full.boxes) == 1
    found = reference.detect(FACE, frame, around=full.boxes[0])
    assert found.region is not None and full.region is None
    assert len(found.boxes) == 1 and contains(found.boxes[0], video.face_centre(0))


def test_a_window_away_from_the_face_finds_nothing() -> None:
    video, _ = scene(FixedPath(0.25, 0.42))
    frame = rgba(video, 0)
    assert reference.detect(FACE, frame, around=(450, 150, 100, 100)).boxes == []


def test_colour_operations_refuse_a_window() -> None:
    frame = np.zeros((48, 80, 4), np.uint8)
    with pytest.raises(ValueError, match="not a cascade"):
        reference.detect(SPEC.op("fire"), frame, around=(0, 0, 10, 10))


def test_full_scan_cadence_and_refind_after_a_jump() -> None:
    video, path = scene(FixedPath(0.25, 0.42))
    tracker = window.Tracker(EVERY)
    scans: list[window.Scan] = []
    jump = 2 * EVERY + 3
    for i in range(3 * EVERY):
        if i == jump:
            path.x = 0.75
        frame = rgba(video, i)
        found, scan = window.step(
            tracker, lambda around, frame=frame: reference.detect(FACE, frame, "default", around)
        )
        scans.append(scan)
        # Every snapshot finds the face where it truly is, the one after the jump included.
        assert contains(window.largest(found.boxes), video.face_centre(i)), (i, scan, found)
    cadence = ["full"] + ["window"] * (EVERY - 1)
    assert scans[:jump] == (cadence * 3)[:jump]
    # The window around the old place is empty after the jump: a full scan at once, then windows.
    assert scans[jump : jump + 2] == ["full", "window"]


def test_thesis_profile_scans_every_frame() -> None:
    assert FACE.thesis["fullScanEvery"] == 1
    tracker = window.Tracker(1)
    tracker.record((0, 0, 10, 10), "full")
    assert tracker.window() is None
