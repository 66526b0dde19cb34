"""The arena's layout: billboards' real sizes, the walk, and the walker facing the robot."""

from __future__ import annotations

import math

import pytest

from app.diffdrive.arena import (
    ARENA,
    FACE_BOX_M,
    FACE_CENTRE_HEIGHT_M,
    WALK,
    Billboard,
    Face,
    Leg,
    Pose2D,
    Walk,
)
from app.diffdrive.sim import ArenaSim


def test_every_billboard_stands_inside_the_arena() -> None:
    for billboard in ARENA.billboards:
        for t in [i * 0.25 for i in range(400)] if billboard.walk else [0.0]:
            pose = billboard.placed(t, (ARENA.start.x, ARENA.start.y))
            assert 0 < pose.x < ARENA.width and 0 < pose.y < ARENA.depth, billboard.name


def test_a_face_photo_is_scaled_so_its_face_box_has_the_real_height() -> None:
    for billboard in ARENA.billboards:
        if not isinstance(billboard.look, Face):
            continue
        photo = billboard.look.photo
        x0, y0, x1, y1 = photo.crop
        picture = billboard.look.picture
        # The picture's height in metres over its height in photo pixels is the scale at which
        # the face box (face_box[3] pixels) measures FACE_BOX_M.
        assert picture.height / (y1 - y0) * photo.face_box[3] == pytest.approx(FACE_BOX_M)
        assert picture.width / picture.height == pytest.approx((x1 - x0) / (y1 - y0))
        # The box's centre at face height: bottom edge + the photo below the centre.
        _, by, _, bh = photo.face_box
        below = (y1 - by - bh / 2) * picture.height / (y1 - y0)
        assert picture.bottom + below == pytest.approx(FACE_CENTRE_HEIGHT_M)


def test_the_walk_passes_its_waypoints_at_the_times_its_speeds_give() -> None:
    walk = Walk((0.0, 0.0), (Leg((2.0, 0.0), 1.0, pause=1.0), Leg((0.0, 0.0), 0.5)))
    assert walk.period_s == pytest.approx(2.0 + 1.0 + 4.0)
    assert walk.at(0.0) == (0.0, 0.0)
    assert walk.at(1.0) == pytest.approx((1.0, 0.0))
    assert walk.at(2.5) == pytest.approx((2.0, 0.0))  # pausing
    assert walk.at(5.0) == pytest.approx((1.0, 0.0))  # half way back at 0.5 m/s
    assert walk.at(7.0 + 1.0) == pytest.approx((1.0, 0.0))  # round again


def test_a_walk_must_come_back_to_its_start() -> None:
    with pytest.raises(ValueError, match="ends where it started"):
        Walk((0.0, 0.0), (Leg((2.0, 0.0), 1.0),))
    with pytest.raises(ValueError, match="positive speed"):
        Walk((0.0, 0.0), (Leg((2.0, 0.0), 0.0), Leg((0.0, 0.0), 1.0)))


def test_a_billboard_has_a_pose_or_a_walk() -> None:
    look = ARENA.billboard("walker").look
    with pytest.raises(ValueError, match="a pose or a walk"):
        Billboard("both", look, pose=Pose2D(1, 1, 0), walk=WALK)
    with pytest.raises(ValueError, match="a pose or a walk"):
        Billboard("neither", look)


def test_the_walker_always_faces_the_robot() -> None:
    walker = ARENA.billboard("walker")
    for t, robot in [(0.0, (1.0, 3.0)), (7.0, (5.0, 1.0)), (13.0, (2.0, 5.0))]:
        pose = walker.placed(t, robot)
        assert (pose.x, pose.y) == WALK.at(t)
        towards = math.atan2(robot[1] - pose.y, robot[0] - pose.x)
        assert math.remainder(pose.yaw - towards, 2 * math.pi) == pytest.approx(0.0, abs=1e-12)


def test_the_walker_dashes_past_the_side_of_a_robot_that_followed_it_to_behind_it() -> None:
    """A robot 1.5 m behind the walker where it pauses at the far end, facing it and not
    turning: the walker leaves its 60° view to the left, then is behind it."""
    times, stretches = WALK._timeline
    # The pause at the end of the first leg, and the dash west after the step north.
    pause_at = next(i for i, s in enumerate(stretches) if s[:2] == s[2:])
    x, y = stretches[pause_at][:2]
    robot = (x - 1.5, y)
    dash = next(i for i, s in enumerate(stretches) if i > pause_at and s[0] - s[2] > 3.0)
    start, end = times[dash], times[dash + 1]
    bearings = [
        math.atan2(WALK.at(t)[1] - robot[1], WALK.at(t)[0] - robot[0])
        for t in [start + (end - start) * k / 50 for k in range(51)]
    ]
    assert abs(bearings[0]) < math.radians(30)  # in view as it sets off
    assert bearings[-1] > math.radians(150)  # ends behind, over the left shoulder
    left_view = next(b for b in bearings if b > math.radians(30))
    assert left_view > 0  # it left the view by the left side, not the right


def test_arena_time_runs_on_ticks_and_moves_the_walker() -> None:
    sim = ArenaSim(clock=lambda: 0.0)
    first = sim.scene()
    for _ in range(125):
        sim.step()
    later = sim.scene()
    assert later.t == pytest.approx(2.0)
    assert later.tick == 125
    walker = [p for p in later.billboards if p.billboard.name == "walker"][0]
    assert (walker.pose.x, walker.pose.y) == pytest.approx(WALK.at(2.0))
    assert first.robot == later.robot  # nobody drove it
