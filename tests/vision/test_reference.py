"""The Python reference pipeline finds what was drawn, where it was drawn."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from app.protocol.relay_profiles import PROFILES
from app.resources import OPERATIONS_SPEC
from app.vision.reference import detect
from app.vision.spec import load_spec
from tests.vision.frames import FACES, Placed, draw_flame, face_crop, paste_face, to_rgba

SPEC = load_spec(OPERATIONS_SPEC)


def inside(point: tuple[float, float] | None, box: Placed, slack: float = 0.0) -> bool:
    """Whether ``point`` lies in ``box`` grown by ``slack`` of its size on each side."""
    assert point is not None
    dx, dy = box.w * slack, box.h * slack
    return (
        box.x - dx <= point[0] <= box.x + box.w + dx
        and box.y - dy <= point[1] <= box.y + box.h + dy
    )


def grey_frame(width: int = 640, height: int = 480) -> np.ndarray:
    return np.full((height, width, 3), 110, np.uint8)


@pytest.mark.parametrize("profile", PROFILES)
def test_fire_finds_a_flame_blob_where_it_was_drawn(profile: str) -> None:
    rng = np.random.default_rng(1)
    frame = grey_frame(1280, 720)
    placed = draw_flame(rng, frame, Placed(900, 400, 160, 200))
    found = detect(SPEC.op("fire"), to_rgba(frame), profile)
    assert len(found.boxes) == 1
    x, y, w, h = found.boxes[0]
    # The box is in full-frame pixels, even when detection ran on a reduced frame.
    assert abs(x - placed.x) <= 8 and abs(y - placed.y) <= 8
    assert abs(w - placed.w) <= 16 and abs(h - placed.h) <= 16
    assert inside(found.target, Placed(930, 450, 100, 100))


def test_fire_takes_the_largest_of_two_blobs() -> None:
    rng = np.random.default_rng(2)
    frame = grey_frame()
    draw_flame(rng, frame, Placed(40, 40, 60, 60))
    big = draw_flame(rng, frame, Placed(400, 250, 160, 160))
    found = detect(SPEC.op("fire"), to_rgba(frame))
    assert inside(found.target, big)


@pytest.mark.parametrize("colour", [(110, 110, 110), (200, 80, 20), (30, 160, 40), (0, 0, 0)])
def test_fire_sees_nothing_without_flame_colours(colour: tuple[int, int, int]) -> None:
    frame = np.full((480, 640, 3), colour, np.uint8)
    cv2.circle(frame, (320, 240), 80, (255, 255, 255), -1)  # white is not flame
    found = detect(SPEC.op("fire"), to_rgba(frame))
    assert found.boxes == [] and found.target is None


def test_fire_ignores_specks_below_min_area() -> None:
    frame = grey_frame()
    cv2.circle(frame, (100, 100), 3, (0, 90, 255), -1)
    assert detect(SPEC.op("fire"), to_rgba(frame)).target is None


@pytest.mark.parametrize("op_id", ["face", "face_small"])
@pytest.mark.parametrize("profile", PROFILES)
def test_face_found_where_it_was_pasted(op_id: str, profile: str) -> None:
    rng = np.random.default_rng(3)
    frame = grey_frame(1280, 720)
    placed = paste_face(rng, frame, face_crop("biden.jpg"), mirror=False, angle=0.0)
    found = detect(SPEC.op(op_id), to_rgba(frame), profile)
    assert found.boxes, "no face found"
    assert inside(found.target, placed)


def test_face_target_is_the_largest_face() -> None:
    crop = face_crop("obama.jpg")
    frame = grey_frame(1280, 720)
    small = cv2.resize(crop, (180, 180), interpolation=cv2.INTER_AREA)
    large = cv2.resize(crop, (360, 360), interpolation=cv2.INTER_AREA)
    frame[40:220, 60:240] = small
    frame[300:660, 820:1180] = large
    found = detect(SPEC.op("face"), to_rgba(frame))
    assert len(found.boxes) == 2
    assert inside(found.target, Placed(820, 300, 360, 360))


def test_face_found_on_a_shared_photo() -> None:
    image = cv2.imread(str(FACES / "obama.jpg"))
    found = detect(SPEC.op("face"), to_rgba(image))
    assert len(found.boxes) == 1
    height, width = image.shape[:2]
    x, y, w, h = found.boxes[0]
    assert 0 <= x and x + w <= width and 0 <= y and y + h <= height and w > width // 5


@pytest.mark.parametrize("op_id", [o.id for o in SPEC.operations])
def test_blank_frame_gives_nothing(op_id: str) -> None:
    found = detect(SPEC.op(op_id), to_rgba(grey_frame()))
    assert found.boxes == [] and found.target is None


def test_bad_frames_and_profiles_are_refused() -> None:
    with pytest.raises(ValueError, match="RGBA"):
        detect(SPEC.op("face"), grey_frame())
    with pytest.raises(ValueError, match="profile"):
        detect(SPEC.op("face"), to_rgba(grey_frame()), "turbo")


class _Cascade:
    """A stand-in classifier that 'finds' fixed boxes (in the image it is given)."""

    def __init__(self, boxes: list[tuple[int, int, int, int]]) -> None:
        self.boxes = boxes

    def detectMultiScale(self, gray: np.ndarray, **_: object) -> np.ndarray:  # noqa: N802
        return np.array(self.boxes, np.int32).reshape(-1, 4)


@pytest.mark.parametrize("profile", PROFILES)
def test_the_body_target_is_the_centre_of_the_largest_box_tall_or_wide(
    monkeypatch: pytest.MonkeyPatch, profile: str
) -> None:
    # Body boxes are not square (a face's are): the target is the centre of the box, x from its
    # width and y from its height. The cascades stand in for what they found, so the test pins
    # the arithmetic, not Haar's recall on a drawing.
    found_by = {
        "haarcascade_fullbody.xml": [(40, 20, 30, 90)],  # tall: the largest
        "haarcascade_upperbody.xml": [(100, 100, 50, 40), (10, 150, 60, 20)],  # wide
    }
    monkeypatch.setattr("app.vision.reference._classifier", lambda name: _Cascade(found_by[name]))
    found = detect(SPEC.op("body"), to_rgba(grey_frame(640, 480)), profile)
    # The default profile detects on a frame reduced to 320 wide: boxes come back doubled.
    factor = 640 / (SPEC.op("body").params_for(profile).detect_width or 640)
    x, y, w, h = (round(v * factor) for v in (40, 20, 30, 90))
    assert (x, y, w, h) in found.boxes and len(found.boxes) == 3
    assert found.target == (x + w / 2, y + h / 2)
    # The largest box wide instead of tall: its centre again.
    found_by["haarcascade_fullbody.xml"] = [(40, 20, 90, 30)]
    found = detect(SPEC.op("body"), to_rgba(grey_frame(640, 480)), profile)
    x, y, w, h = (round(v * factor) for v in (40, 20, 90, 30))
    assert found.target == (x + w / 2, y + h / 2)
