"""The control law of DESIGN §5 / docs/contracts.md, with an injected clock."""

from __future__ import annotations

import math

import pytest

from vehicle_agent.control import (
    PROFILES,
    TERRAIN_CENTRE,
    Controller,
    Goal,
    Pose,
    pixel_to_terrain,
    steering_error,
    wrap_angle,
)

CENTRE = Pose(TERRAIN_CENTRE, TERRAIN_CENTRE, 0.0)


def pixel_towards(degrees: float, distance_m: float = 3.0) -> Goal:
    """A goal pixel of a 640×480 frame whose terrain point lies at ``degrees`` from the centre."""
    tx = TERRAIN_CENTRE + distance_m * math.cos(math.radians(degrees))
    ty = TERRAIN_CENTRE + distance_m * math.sin(math.radians(degrees))
    return Goal(tx * 320 / TERRAIN_CENTRE, 480 - ty * 240 / TERRAIN_CENTRE, 640, 480)


class FakeClock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_pixel_to_terrain_maps_frame_corners_and_centre_onto_the_terrain() -> None:
    size = 2 * TERRAIN_CENTRE
    assert pixel_to_terrain(320, 240, 640, 480) == pytest.approx((TERRAIN_CENTRE, TERRAIN_CENTRE))
    # Top-left pixel of the image is the top-left of the terrain: x = 0, y = world size.
    assert pixel_to_terrain(0, 0, 640, 480) == pytest.approx((0.0, size))
    assert pixel_to_terrain(640, 480, 640, 480) == pytest.approx((size, 0.0))
    # The scale is per axis, so a non-square frame still fills the square terrain.
    assert pixel_to_terrain(1280, 0, 1280, 720) == pytest.approx((size, size))


def test_image_y_down_is_terrain_y_up() -> None:
    """A face above the image centre is a target above the turtle: it turns left (θ > 0)."""
    up = steering_error(Goal(320, 40, 640, 480), CENTRE)
    down = steering_error(Goal(320, 440, 640, 480), CENTRE)
    assert up == pytest.approx(math.pi / 2)
    assert down == pytest.approx(-math.pi / 2)


def test_face_on_the_right_or_left_side_of_the_frame() -> None:
    right = steering_error(Goal(600, 240, 640, 480), CENTRE)
    left = steering_error(Goal(40, 240, 640, 480), CENTRE)
    assert right == pytest.approx(0.0)
    assert left == pytest.approx(math.pi)


def test_wrap_angle_range_is_half_open() -> None:
    assert wrap_angle(math.pi) == pytest.approx(math.pi)
    assert wrap_angle(-math.pi) == pytest.approx(math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
    assert wrap_angle(7 * math.pi) == pytest.approx(math.pi)
    assert wrap_angle(0.25) == pytest.approx(0.25)


def test_steering_takes_the_short_way_across_the_wrap() -> None:
    """Turtle at θ = 170°, target at −170° (lower left): turn +20°, not −340°.

    The thesis's case split subtracts the raw angles (−170° − 170° = −340°) and turns the
    long way round; wrapping the difference gives the short turn.
    """
    pose = Pose(TERRAIN_CENTRE, TERRAIN_CENTRE, math.radians(170))
    error = steering_error(pixel_towards(-170), pose)
    assert error == pytest.approx(math.radians(20))


def test_target_on_the_turtle_has_no_heading() -> None:
    assert steering_error(Goal(320, 240, 640, 480), CENTRE) is None


def test_default_profile_publishes_on_pose_updates_at_most_every_50_ms() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["default"], clock)
    assert control.pose(CENTRE) is None  # no goal yet
    control.goal(Goal(320, 40, 640, 480, seq=1, frame=7))
    published = []
    for _ in range(20):  # 20 pose updates 16 ms apart = 320 ms
        twist = control.pose(CENTRE)
        if twist is not None:
            published.append((clock.now, twist))
        clock.now += 0.016
    times = [t for t, _ in published]
    assert len(published) >= 4
    assert all(b - a >= 0.05 for a, b in zip(times, times[1:], strict=False))
    first = published[0][1]
    # +90° error, gain 6 → clamped to the 4 rad/s limit; the goal's tags ride along.
    assert first.angular_z == pytest.approx(4.0)
    assert first.linear_x == 0.0
    assert (first.seq, first.frame) == (1, 7)


def test_default_profile_is_proportional_with_a_deadband() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["default"], clock)
    control.goal(pixel_towards(5))
    twist = control.pose(CENTRE)
    assert twist is not None
    assert twist.angular_z == pytest.approx(6.0 * math.radians(5), rel=1e-6)
    clock.now += 0.1
    # Facing the target already: inside the 0.01 rad deadband, the command is zero.
    control.goal(Goal(600, 240, 640, 480))
    twist = control.pose(CENTRE)
    assert twist is not None and twist.angular_z == 0.0


def test_goal_timeout_gives_one_zero_twist_then_nothing() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["default"], clock)
    control.goal(Goal(320, 40, 640, 480))
    assert control.pose(CENTRE) is not None
    clock.now += 0.7
    assert control.tick() is None  # still inside 0.75 s
    clock.now += 0.1
    stop = control.tick()
    assert stop is not None and stop.is_zero
    assert not control.active
    clock.now += 1.0
    assert control.tick() is None
    assert control.pose(CENTRE) is None


def test_stop_gives_one_zero_twist_only_when_driving() -> None:
    control = Controller(PROFILES["default"], FakeClock())
    assert control.stop() is None
    control.goal(Goal(320, 40, 640, 480))
    stop = control.stop()
    assert stop is not None and stop.is_zero
    assert control.stop() is None


def test_thesis_profile_publishes_the_latest_goal_every_1100_ms() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["thesis"], clock)
    control.pose(CENTRE)
    published = []

    def run_until(t_end: float) -> None:
        while clock.now < t_end:
            twist = control.tick()
            if twist is not None:
                published.append((round(clock.now - 100.0, 3), twist))
            clock.now = round(clock.now + 0.01, 6)

    # First goal: face straight up → +90°, published at once.
    first = control.goal(Goal(320, 40, 640, 480, seq=1))
    assert first is not None and first.angular_z == pytest.approx(math.pi / 2)
    assert first.seq == 1
    published.append((0.0, first))
    run_until(100.5)
    # Two newer goals inside the period: only the latest counts at the next publish.
    control.goal(Goal(40, 240, 640, 480, seq=2))  # left: +180°
    run_until(100.8)
    control.goal(Goal(320, 440, 640, 480, seq=3))  # down: −90°
    run_until(102.3)
    # Goals every 2 s keep the 2.5 s timeout away.
    times = [t for t, _ in published]
    assert times == pytest.approx([0.0, 1.1, 2.2], abs=0.011)
    assert [tw.seq for _, tw in published] == [1, 3, 3]
    # angular.z is the steering error itself: turtlesim runs it for 1 s, turning by e.
    assert published[1][1].angular_z == pytest.approx(-math.pi / 2)


def test_thesis_profile_times_out_after_2_5_s() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["thesis"], clock)
    control.pose(CENTRE)
    control.goal(Goal(320, 40, 640, 480))
    clock.now += 2.4
    assert control.tick() is not None  # a regular publish, not a stop
    clock.now += 0.2
    stop = control.tick()
    assert stop is not None and stop.is_zero
