"""The onboard camera: where billboards land in the frame, what hides what, and that the face
operations find the faces it renders where the projection says they are."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from app.diffdrive.arena import (
    ARENA,
    FACE_BOX_M,
    FACE_CENTRE_HEIGHT_M,
    Billboard,
    Face,
    FacePhoto,
    Picture,
    Pose2D,
)
from app.diffdrive.camera import (
    NEAR_M,
    Image,
    Pinhole,
    Renderer,
    encode_jpeg,
    load_face,
    visible_part,
)
from app.diffdrive.robot import RobotState
from app.diffdrive.sim import Placed, Scene
from app.protocol.control import PROFILES, for_robot
from app.protocol.robot import PRESETS
from app.resources import OPERATIONS_SPEC
from app.vision import reference
from app.vision.spec import load_spec
from vehicle_agent.core.control import pixel_bearing

CAMERA = Pinhole()  # 640x480, 60° across
ROBOT = RobotState(2.0, 3.0, 0.0, 0.0, 0.0)  # facing east, the arena's long way
WALKER = ARENA.billboard("walker")
BYSTANDER = ARENA.billboard("bystander")
FLAME = ARENA.billboard("flame")


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    return Renderer(ARENA, CAMERA)


def scene(*placed: tuple[Billboard, float, float, float], robot: RobotState = ROBOT) -> Scene:
    """The robot and these billboards at (x, y, yaw)."""
    return Scene(0.0, robot, tuple(Placed(b, Pose2D(x, y, yaw)) for b, x, y, yaw in placed), 0)


def ahead(distance: float, bearing: float = 0.0, robot: RobotState = ROBOT) -> tuple[float, float]:
    """The arena point ``distance`` from the robot at ``bearing`` (positive: left)."""
    heading = robot.yaw + bearing
    return robot.x + distance * math.cos(heading), robot.y + distance * math.sin(heading)


def facing_robot(
    billboard: Billboard, distance: float, bearing: float = 0.0
) -> tuple[Billboard, float, float, float]:
    x, y = ahead(distance, bearing)
    return billboard, x, y, math.atan2(ROBOT.y - y, ROBOT.x - x)


def changed(frame: Image, empty: Image) -> npt.NDArray[np.bool_]:
    """Where ``frame`` differs from the empty arena's frame."""
    return np.asarray(np.any(frame != empty, axis=2))


def box_of(mask: npt.NDArray[np.bool_]) -> tuple[float, float, float, float]:
    """(left, top, right, bottom) of the True pixels, in continuous pixel coordinates."""
    rows, cols = np.nonzero(mask)
    return float(cols.min()), float(rows.min()), float(cols.max() + 1), float(rows.max() + 1)


def test_the_projection_puts_a_point_ahead_at_the_centre_and_one_to_the_left_left() -> None:
    centre = CAMERA.project(ROBOT, *ahead(3.0), CAMERA.mount_height)
    assert centre == pytest.approx((320.0, 240.0))
    left = CAMERA.project(ROBOT, *ahead(3.0, math.radians(20)), CAMERA.mount_height)
    assert left is not None and left[0] < 320.0
    # The bearing read back from the pixel, as the onboard law reads a goal's.
    assert CAMERA.pixel_bearing(left[0]) == pytest.approx(math.radians(20))
    assert CAMERA.bearing(ROBOT, *ahead(3.0, math.radians(20))) == pytest.approx(math.radians(20))
    # Higher is up in the frame; behind is nowhere.
    high = CAMERA.project(ROBOT, *ahead(3.0), CAMERA.mount_height + 1.0)
    assert high is not None and high[1] < 240.0
    assert CAMERA.project(ROBOT, *ahead(3.0, math.pi), 1.0) is None


def test_the_focal_length_follows_the_field_of_view() -> None:
    # The frame's edge is half the field of view off the axis.
    for hfov in (math.radians(45), math.radians(60), math.radians(90)):
        camera = Pinhole(hfov=hfov)
        assert camera.pixel_bearing(0.0) == pytest.approx(hfov / 2)
        assert camera.pixel_bearing(640.0) == pytest.approx(-hfov / 2)
    with pytest.raises(ValueError, match="field of view"):
        Pinhole(hfov=math.pi)


def test_the_empty_arena_is_not_uniform_and_turning_changes_it(renderer: Renderer) -> None:
    frame = renderer.render(scene())
    assert frame.shape == (480, 640, 3) and frame.dtype == np.uint8
    # Ceiling, walls and floor differ, and the walls darken with distance.
    assert float(frame.std()) > 15
    colours = frame.reshape(-1, 3).astype(np.int64) @ np.array([1 << 16, 1 << 8, 1])
    assert len(np.unique(colours)) > 50
    turned = renderer.render(scene(robot=RobotState(2.0, 3.0, 0.4, 0.0, 0.0)))
    assert np.mean(turned != frame) > 0.05


def test_a_billboard_straight_ahead_is_centred(renderer: Renderer) -> None:
    empty = renderer.render(scene())
    frame = renderer.render(scene(facing_robot(WALKER, 2.5)))
    left, top, right, _ = box_of(changed(frame, empty))
    assert (left + right) / 2 == pytest.approx(320.0, abs=1.0)
    # The photo's top edge is where the projection puts it.
    picture = WALKER.look.picture
    expected_top = CAMERA.project(ROBOT, *ahead(2.5), picture.bottom + picture.height)
    assert expected_top is not None
    assert top == pytest.approx(expected_top[1], abs=1.0)


@pytest.mark.parametrize("degrees", [15.0, -15.0])
def test_a_billboard_to_one_side_appears_on_that_side(renderer: Renderer, degrees: float) -> None:
    empty = renderer.render(scene())
    bearing = math.radians(degrees)
    frame = renderer.render(scene(facing_robot(WALKER, 2.5, bearing)))
    left, _, right, _ = box_of(changed(frame, empty))
    centre = (left + right) / 2
    # Positive bearings (to the robot's left) land left of the centre, as yaw turns.
    assert (centre < 320.0) == (degrees > 0)
    projected = CAMERA.project(ROBOT, *ahead(2.5, bearing), FACE_CENTRE_HEIGHT_M)
    assert projected is not None
    assert centre == pytest.approx(projected[0], abs=1.5)


def test_a_billboard_behind_the_camera_is_not_drawn(renderer: Renderer) -> None:
    empty = renderer.render(scene())
    for bearing in (math.pi, math.radians(100), math.radians(-120)):
        frame = renderer.render(scene(facing_robot(WALKER, 1.5, bearing)))
        assert not changed(frame, empty).any()


def test_a_picture_across_the_clipping_plane_is_cut_along_it() -> None:
    """A picture 0.4 m wide from 0.1 m behind the camera to 0.3 m ahead: its first quarter
    (to the clipping plane 0.05 m ahead) is cut off, and the kept part's near corners are the
    projections of the points where the plane cuts it."""
    picture = Picture(0.4, 0.5, 1.2)
    pose = Pose2D(ROBOT.x + 0.1, ROBOT.y + 0.15, -math.pi / 2)  # facing south, across the path
    part = visible_part(CAMERA, ROBOT, pose, picture)
    assert part is not None
    assert part.start == pytest.approx((0.1 + NEAR_M) / 0.4)
    assert part.end == 1.0
    cut_top = CAMERA.project(ROBOT, ROBOT.x + NEAR_M + 1e-12, ROBOT.y + 0.15, 1.7)
    far_bottom = CAMERA.project(ROBOT, ROBOT.x + 0.3, ROBOT.y + 0.15, 1.2)
    assert cut_top is not None and far_bottom is not None
    assert part.corners[0] == pytest.approx(cut_top)
    assert part.corners[2] == pytest.approx(far_bottom)
    # Turned round, the same picture is cut at its other end; wholly behind, nothing is left.
    turned = visible_part(CAMERA, ROBOT, Pose2D(pose.x, pose.y, math.pi / 2), picture)
    assert turned is not None
    assert (turned.start, turned.end) == pytest.approx((0.0, 1 - (0.1 + NEAR_M) / 0.4))
    behind = Pose2D(ROBOT.x - 0.5, ROBOT.y, 0.0)
    assert visible_part(CAMERA, ROBOT, behind, picture) is None


def test_a_billboard_half_behind_the_camera_shows_its_front_half(renderer: Renderer) -> None:
    """Just left of the robot and facing across its path, the picture reaches from behind the
    camera to 0.3 m ahead of it: the part behind the clipping plane is cut off, the rest is
    drawn from the frame's left edge to where its far edge projects."""
    empty = renderer.render(scene())
    width = WALKER.look.picture.width
    # Facing south, its far (right) edge 0.3 m ahead of the camera and 0.15 m to the left.
    board = (WALKER, ROBOT.x + 0.3 - width / 2, ROBOT.y + 0.15, -math.pi / 2)
    mask = changed(renderer.render(scene(board)), empty)
    left, _, right, _ = box_of(mask)
    far_edge = CAMERA.project(ROBOT, ROBOT.x + 0.3, ROBOT.y + 0.15, CAMERA.mount_height)
    assert far_edge is not None
    assert left == 0.0
    assert right == pytest.approx(far_edge[0], abs=1.0)


def test_nearer_billboards_hide_farther_ones_whatever_their_order(renderer: Renderer) -> None:
    empty = renderer.render(scene())
    near = facing_robot(FLAME, 1.6, math.radians(3))
    far = facing_robot(WALKER, 3.0)
    near_only = renderer.render(scene(near))
    far_only = renderer.render(scene(far))
    both = renderer.render(scene(far, near))
    near_mask, far_mask = changed(near_only, empty), changed(far_only, empty)
    overlap = near_mask & far_mask
    assert overlap.sum() > 500  # they do overlap in the frame
    assert np.array_equal(both[near_mask], near_only[near_mask])
    assert np.array_equal(both[far_mask & ~near_mask], far_only[far_mask & ~near_mask])
    assert np.array_equal(renderer.render(scene(near, far)), both)


def test_a_billboard_seen_from_behind_shows_a_blank_back(renderer: Renderer) -> None:
    x, y = ahead(2.0)
    front = renderer.render(scene((WALKER, x, y, math.pi)))
    back = renderer.render(scene((WALKER, x, y, 0.0)))
    spec = load_spec(OPERATIONS_SPEC)
    assert reference.detect(spec.op("face"), rgba(front)).boxes
    assert not reference.detect(spec.op("face"), rgba(back)).boxes


def rgba(bgr: Image) -> Image:
    """A frame as the relay's worker gets it: through JPEG, as RGBA."""
    decoded = cv2.imdecode(np.frombuffer(encode_jpeg(bgr), np.uint8), cv2.IMREAD_COLOR)
    return np.asarray(cv2.cvtColor(decoded, cv2.COLOR_BGR2RGBA), dtype=np.uint8)


@pytest.mark.parametrize(
    ("op", "distance"), [("face", 1.0), ("face", 2.0), ("face_small", 3.0), ("face_small", 4.0)]
)
def test_the_face_operations_find_a_rendered_face_where_the_projection_puts_it(
    renderer: Renderer, op: str, distance: float
) -> None:
    """The default face operation finds the walker's face up to 2 m (its smallest box is 60 px
    in a 640 px frame); the small-face operation farther. The box is centred on the face's
    projected centre and its height is the face box's real height seen from there."""
    bearing = math.radians(10)
    frame = renderer.render(scene(facing_robot(WALKER, distance, bearing)))
    found = reference.detect(load_spec(OPERATIONS_SPEC).op(op), rgba(frame))
    assert len(found.boxes) == 1
    x, y, w, h = found.boxes[0]
    projected = CAMERA.project(ROBOT, *ahead(distance, bearing), FACE_CENTRE_HEIGHT_M)
    assert projected is not None
    tolerance = max(3.0, 0.1 * h)
    assert x + w / 2 == pytest.approx(projected[0], abs=tolerance)
    assert y + h / 2 == pytest.approx(projected[1], abs=tolerance)
    assert h == pytest.approx(CAMERA.focal * FACE_BOX_M / distance, rel=0.15)


@pytest.mark.parametrize("degrees", [-20.0, -10.0, -3.0, 0.0, 3.0, 10.0, 20.0])
def test_the_onboard_law_reads_a_rendered_face_at_its_true_bearing(
    renderer: Renderer, degrees: float
) -> None:
    """The simulator's camera and the onboard law agree: the walker rendered at a known bearing,
    found by the operation the bench follows it with, is at that bearing by the law's
    pixel-to-bearing conversion (the robot description's field of view, the frame's width)."""
    law = for_robot(PROFILES["onboard"], PRESETS["diffdrive"])
    frame = renderer.render(scene(facing_robot(WALKER, 1.5, math.radians(degrees))))
    found = reference.detect(load_spec(OPERATIONS_SPEC).op("face_small"), rgba(frame))
    assert found.target is not None
    bearing = pixel_bearing(found.target[0], frame.shape[1], law.hfov)
    assert math.degrees(bearing) == pytest.approx(degrees, abs=0.5)


def test_both_faces_of_the_arena_are_found_side_by_side(renderer: Renderer) -> None:
    frame = renderer.render(
        scene(facing_robot(WALKER, 1.8, math.radians(12)), facing_robot(BYSTANDER, 1.8, -0.2))
    )
    found = reference.detect(load_spec(OPERATIONS_SPEC).op("face"), rgba(frame))
    assert len(found.boxes) == 2


def test_the_flame_is_found_by_the_fire_operation(renderer: Renderer) -> None:
    frame = renderer.render(scene(facing_robot(FLAME, 3.0, math.radians(-8))))
    found = reference.detect(load_spec(OPERATIONS_SPEC).op("fire"), rgba(frame))
    assert found.target is not None
    picture = FLAME.look.picture
    middle = CAMERA.project(
        ROBOT, *ahead(3.0, math.radians(-8)), picture.bottom + picture.height / 2
    )
    assert middle is not None
    assert found.target[0] == pytest.approx(middle[0], abs=6.0)


def test_a_photo_that_is_not_the_one_measured_is_refused(tmp_path: Path) -> None:
    look = WALKER.look
    assert isinstance(look, Face)
    shrunk = cv2.resize(cv2.imread(str(Path("app/assets") / look.photo.file)), (100, 125))
    cv2.imwrite(str(tmp_path / look.photo.file), shrunk)
    with pytest.raises(ValueError, match="not the 910x1137 photo"):
        load_face(look, tmp_path)
    missing = Face(FacePhoto("nobody.jpg", (10, 10), (1, 1, 5, 5)))
    with pytest.raises(ValueError, match="cannot read"):
        load_face(missing, tmp_path)


def test_a_frame_encodes_as_a_jpeg_of_the_frame_size(renderer: Renderer) -> None:
    data = encode_jpeg(renderer.render(scene(facing_robot(WALKER, 2.0))))
    assert data[:2] == b"\xff\xd8"
    decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert decoded.shape == (480, 640, 3)
