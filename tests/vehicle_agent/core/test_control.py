"""The control laws and the controller (docs/architecture.md, "Vehicle control"), with the time
given by the test."""

from __future__ import annotations

import math

import pytest

from app.protocol.control import for_robot, with_standoff
from app.protocol.robot import PRESETS, TURTLESIM
from app.turtlesim.sim import Pose as SimPose
from app.turtlesim.sim import TurtleSim
from vehicle_agent.core.control import (
    PROFILES,
    TERRAIN_CENTRE,
    Controller,
    Goal,
    Pose,
    follow_command,
    pixel_to_terrain,
    steering_error,
    wall_clearance,
    wrap_angle,
)
from vehicle_agent.core.limits import Limiter

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
    control = Controller(PROFILES["default"])
    assert control.pose(CENTRE, clock.now) is None  # no goal yet
    control.goal(Goal(320, 40, 640, 480, seq=1, frame=7), clock.now)
    published = []
    for _ in range(20):  # 20 pose updates 16 ms apart = 320 ms
        twist = control.pose(CENTRE, clock.now)
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
    control = Controller(PROFILES["default"])
    control.pose(CENTRE, clock.now)
    twist = control.goal(pixel_towards(5), clock.now)
    assert twist is not None
    assert twist.angular_z == pytest.approx(6.0 * math.radians(5), rel=1e-6)
    clock.now += 0.1
    # Facing the target already: inside the 0.01 rad deadband, the command is zero.
    twist = control.goal(Goal(600, 240, 640, 480), clock.now)
    assert twist is not None and twist.angular_z == 0.0


def test_goal_timeout_gives_one_zero_twist_then_nothing() -> None:
    clock = FakeClock()
    timeout = PROFILES["default"].goal_timeout_s
    # The field target: a vehicle that loses its goals stops within 0.75 s of the last one.
    assert timeout <= 0.75
    control = Controller(PROFILES["default"])
    control.goal(Goal(320, 40, 640, 480), clock.now)
    assert control.until_timeout(clock.now) == pytest.approx(timeout)
    assert control.pose(CENTRE, clock.now) is not None
    clock.now += timeout - 0.01
    assert control.tick(clock.now) is None  # still inside the timeout
    assert control.until_timeout(clock.now) == pytest.approx(0.01)
    clock.now += 0.01
    stop = control.tick(clock.now)  # due at the timeout itself, not a tick later
    assert stop is not None and stop.is_zero
    assert not control.active
    assert control.until_timeout(clock.now) is None
    clock.now += 1.0
    assert control.tick(clock.now) is None
    assert control.pose(CENTRE, clock.now) is None


def test_stop_gives_one_zero_twist_only_when_driving() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["default"])
    assert control.stop() is None
    control.goal(Goal(320, 40, 640, 480), clock.now)
    stop = control.stop()
    assert stop is not None and stop.is_zero
    assert control.stop() is None


def test_thesis_profile_publishes_the_latest_goal_every_1100_ms() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["thesis"])
    control.pose(CENTRE, clock.now)
    published = []

    def run_until(t_end: float) -> None:
        while clock.now < t_end:
            twist = control.tick(clock.now)
            if twist is not None:
                published.append((round(clock.now - 100.0, 3), twist))
            clock.now = round(clock.now + 0.01, 6)

    # First goal: face straight up → +90°, published at once.
    first = control.goal(Goal(320, 40, 640, 480, seq=1), clock.now)
    assert first is not None and first.angular_z == pytest.approx(math.pi / 2)
    assert first.seq == 1
    published.append((0.0, first))
    run_until(100.5)
    # Two newer goals inside the period: only the latest counts at the next publish.
    control.goal(Goal(40, 240, 640, 480, seq=2), clock.now)  # left: +180°
    run_until(100.8)
    control.goal(Goal(320, 440, 640, 480, seq=3), clock.now)  # down: −90°
    run_until(102.3)
    # Goals every 2 s keep the 2.5 s timeout away.
    times = [t for t, _ in published]
    assert times == pytest.approx([0.0, 1.1, 2.2], abs=0.011)
    assert [tw.seq for _, tw in published] == [1, 3, 3]
    # angular.z is the steering error itself: turtlesim runs it for 1 s, turning by e.
    assert published[1][1].angular_z == pytest.approx(-math.pi / 2)


def test_thesis_profile_times_out_after_2_5_s() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["thesis"])
    control.pose(CENTRE, clock.now)
    control.goal(Goal(320, 40, 640, 480), clock.now)
    clock.now += 2.4
    assert control.tick(clock.now) is not None  # a regular publish, not a stop
    clock.now += 0.2
    stop = control.tick(clock.now)
    assert stop is not None and stop.is_zero


def test_default_profile_answers_a_goal_at_once() -> None:
    """A Twist as soon as a goal lands, not at the next pose update."""
    clock = FakeClock()
    control = Controller(PROFILES["default"])
    assert control.goal(Goal(320, 40, 640, 480, seq=1, frame=3), clock.now) is None  # no pose yet
    control.pose(CENTRE, clock.now)  # the first pose answers the waiting goal
    clock.now += 0.2
    twist = control.goal(Goal(600, 240, 640, 480, seq=2, frame=9), clock.now)
    assert twist is not None and (twist.seq, twist.frame) == (2, 9)
    # Goals at 30 fps: every one is answered the moment it arrives, none waits for a pose.
    for k in range(3, 13):
        clock.now += 1 / 30
        answer = control.goal(Goal(40, 240, 640, 480, seq=k, frame=k), clock.now)
        assert answer is not None and answer.seq == k, k


def test_goal_answers_are_rate_capped_and_the_next_pose_delivers_a_capped_goal() -> None:
    clock = FakeClock()
    profile = PROFILES["default"]
    control = Controller(profile)
    control.pose(CENTRE, clock.now)
    assert control.goal(Goal(320, 40, 640, 480, seq=1), clock.now) is not None
    # A second goal well inside the command-rate cap is held back ...
    clock.now += profile.min_interval_s / 4
    assert control.goal(Goal(40, 240, 640, 480, seq=2), clock.now) is None
    # ... and a pose before the cap has passed does not send it either ...
    clock.now += profile.min_interval_s / 4
    assert control.pose(CENTRE, clock.now) is None
    # ... but the first pose after the cap does, well before the 50 ms pose period.
    clock.now += profile.min_interval_s
    assert clock.now - 100.0 < profile.period_s
    twist = control.pose(CENTRE, clock.now)
    assert twist is not None and twist.seq == 2
    # Answered: poses go back to the 50 ms period.
    clock.now += 0.016
    assert control.pose(CENTRE, clock.now) is None


def test_thesis_profile_keeps_its_pacing_when_goals_arrive() -> None:
    clock = FakeClock()
    control = Controller(PROFILES["thesis"])
    control.pose(CENTRE, clock.now)
    assert control.goal(Goal(320, 40, 640, 480, seq=1), clock.now) is not None
    for k in range(2, 30):  # goals at 30 fps for ~1 s: none is answered on arrival
        clock.now += 1 / 30
        assert control.goal(Goal(320, 40, 640, 480, seq=k), clock.now) is None
        assert control.pose(CENTRE, clock.now) is None
    clock.now = 100.0 + 1.11
    assert control.tick(clock.now) is not None


# --- the follow profile ------------------------------------------------------------------------


def terrain_goal(tx: float, ty: float, seq: int = 0) -> Goal:
    """The goal pixel of a 640×480 frame whose terrain point is (tx, ty)."""
    return Goal(tx * 320 / TERRAIN_CENTRE, 480 - ty * 240 / TERRAIN_CENTRE, 640, 480, seq=seq)


def drive(control: Controller, sim: TurtleSim, clock: FakeClock, seconds: float) -> None:
    """Run the simulator and the controller together, one turtlesim tick at a time, each
    command held to a turtlesim's top speeds as the pilot holds it (the laws ask for more)."""
    limiter = Limiter(TURTLESIM.limits, TurtleSim.TICK_S)
    for _ in range(round(seconds / TurtleSim.TICK_S)):
        clock.now += TurtleSim.TICK_S
        sim.step()
        p = sim.pose("turtle1")
        twist = control.pose(Pose(p.x, p.y, p.theta), clock.now) or control.tick(clock.now)
        if twist is not None:
            sent = limiter.command(twist, clock.now)
            sim.cmd_vel("turtle1", sent.linear_x, sent.angular_z)


def chase(
    control: Controller, sim: TurtleSim, clock: FakeClock, target: tuple[float, float], goals: int
) -> SimPose:
    """Goals at ``target`` at 30 fps, ``goals`` of them, driving in between; the pose after."""
    for k in range(goals):
        control.goal(terrain_goal(*target, seq=k), clock.now)
        drive(control, sim, clock, 1 / 30)
    return sim.pose("turtle1")


def follow_world() -> tuple[Controller, TurtleSim, FakeClock]:
    clock = FakeClock()
    sim = TurtleSim(clock=clock)
    return Controller(PROFILES["follow"]), sim, clock


def test_follow_drives_to_the_standoff_from_the_target() -> None:
    control, sim, clock = follow_world()
    target = (2.0, 8.0)
    p = chase(control, sim, clock, target, goals=150)  # 5 s
    distance = math.hypot(p.x - target[0], p.y - target[1])
    assert distance == pytest.approx(PROFILES["follow"].standoff_m, abs=0.05)
    # It faces the target it stopped short of.
    error = steering_error(terrain_goal(*target), Pose(p.x, p.y, p.theta))
    assert error is not None and abs(error) < 0.05


def test_follow_backs_off_when_the_target_comes_too_close() -> None:
    control, sim, clock = follow_world()
    centre = TurtleSim.CENTRE
    target = (centre + 0.4, centre)  # straight ahead, inside the 1 m standoff
    control.pose(Pose(centre, centre, 0.0), clock.now)
    twist = control.goal(terrain_goal(*target), clock.now)
    assert twist is not None and twist.linear_x < 0
    p = chase(control, sim, clock, target, goals=90)
    assert math.hypot(p.x - target[0], p.y - target[1]) == pytest.approx(1.0, abs=0.05)


def test_follow_standoff_is_settable() -> None:
    clock = FakeClock()
    sim = TurtleSim(clock=clock)
    control = Controller(with_standoff(PROFILES["follow"], 2.5))
    target = (9.0, 5.544445)
    p = chase(control, sim, clock, target, goals=150)
    assert math.hypot(p.x - target[0], p.y - target[1]) == pytest.approx(2.5, abs=0.05)


@pytest.mark.parametrize(
    "target", [(11.088889, 5.5), (0.0, 0.0), (5.5, 11.088889), (11.088889, 11.088889)]
)
def test_follow_never_pins_itself_against_a_wall(target: tuple[float, float]) -> None:
    """A target on the edge of the world (a face at the edge of the frame)."""
    profile = PROFILES["follow"]
    control, sim, clock = follow_world()
    closest = math.inf
    for k in range(240):
        control.goal(terrain_goal(*target, seq=k), clock.now)
        drive(control, sim, clock, 1 / 30)
        p = sim.pose("turtle1")
        closest = min(closest, p.x, p.y, sim.WORLD_SIZE - p.x, sim.WORLD_SIZE - p.y)
    # It stopped short of the wall and was never clamped onto it.
    assert closest >= profile.wall_margin_m - 0.05
    # Still free to move: it turns away when the target moves back into the world.
    inside = (TurtleSim.CENTRE, TurtleSim.CENTRE)
    p = chase(control, sim, clock, inside, goals=150)
    assert math.hypot(p.x - inside[0], p.y - inside[1]) == pytest.approx(1.0, abs=0.1)


def test_follow_slows_near_a_wall() -> None:
    profile = PROFILES["follow"]

    def speed(pose: Pose, target: tuple[float, float]) -> float:
        """The speed published: the law's, within a turtlesim's top speed."""
        clock = FakeClock()
        control = Controller(profile)
        control.pose(pose, clock.now)
        twist = control.goal(terrain_goal(*target), clock.now)
        assert twist is not None
        return Limiter(TURTLESIM.limits, TurtleSim.TICK_S).command(twist, clock.now).linear_x

    # The same 3 m to go, facing the target: in the open the turtle drives at full speed (4 m/s,
    # a turtlesim's top), towards a target at the wall it is already slowing down.
    open_speed = speed(Pose(3.0, 5.5, 0.0), (6.0, 5.5))
    wall_target = (TurtleSim.WORLD_SIZE, 5.5)
    inside = TurtleSim.WORLD_SIZE - profile.wall_margin_m  # the target is kept this far in
    wall_speed = speed(Pose(inside - 3.0, 5.5, 0.0), wall_target)
    assert open_speed == 4.0
    assert 0.0 < wall_speed < open_speed
    # Backing off from a target that came too close, with a wall behind: slower and slower,
    # and not at all inside the wall margin.
    backing = [speed(Pose(x, 5.5, 0.0), (x + 0.5, 5.5)) for x in (3.0, 1.0, 0.6, 0.45)]
    assert backing[0] < 0.0
    assert backing[0] <= backing[1] < backing[2] < backing[3] == 0.0


def test_follow_knows_of_walls_on_a_turtlesim_only() -> None:
    # The same target 3 m ahead, at the turtlesim terrain's wall: a turtlesim slows down for
    # the wall; a robot whose surroundings are not that terrain (odometry's origin is wherever
    # it started) drives at full speed, and aims at the point itself, not one kept inside.
    turtlesim = for_robot(PROFILES["follow"], PRESETS["turtlesim"])
    rover = for_robot(PROFILES["follow"], PRESETS["diffdrive"])
    assert turtlesim.walls and not rover.walls
    # The law asks for 3.0 m/s per metre beyond the 1 m standoff, facing it the whole of the top
    # speed (the pilot's limiter holds it to the robot's).
    pose = Pose(TurtleSim.WORLD_SIZE - 3.0, 5.5, 0.0)
    near_wall = follow_command(TurtleSim.WORLD_SIZE, 5.5, pose, turtlesim)
    anywhere = follow_command(TurtleSim.WORLD_SIZE, 5.5, pose, rover)
    assert (anywhere.linear_x, anywhere.angular_z, anywhere.top_share) == (6.0, 0.0, 1.0)
    assert 0.0 < near_wall.linear_x < anywhere.linear_x
    # A point beyond what would be the terrain's edge, straight ahead: a robot heads for it;
    # a turtlesim aims at the point kept inside its terrain, and so turns.
    outside = Pose(TurtleSim.WORLD_SIZE + 2.0, -1.0, math.pi / 2)
    ahead = follow_command(TurtleSim.WORLD_SIZE + 2.0, 4.0, outside, rover)
    assert (ahead.linear_x, ahead.angular_z) == pytest.approx((3.0 * (5.0 - 1.0), 0.0))
    assert follow_command(TurtleSim.WORLD_SIZE + 2.0, 4.0, outside, turtlesim).angular_z > 0.5


def test_follow_searches_in_place_when_the_target_is_lost() -> None:
    profile = PROFILES["follow"]
    control, sim, clock = follow_world()
    # Seen on the left (counter-clockwise side), then lost.
    chase(control, sim, clock, (3.0, 8.0), goals=30)
    assert not control.searching(clock.now)
    drive(control, sim, clock, profile.search_after_s * 0.9)
    assert not control.searching(clock.now)
    drive(control, sim, clock, profile.search_after_s * 0.2)
    assert control.searching(clock.now)
    before = sim.pose("turtle1")
    drive(control, sim, clock, 1.0)
    after = sim.pose("turtle1")
    # Turning in place, towards the side the target was last seen on.
    assert (after.x, after.y) == pytest.approx((before.x, before.y), abs=1e-9)
    assert wrap_angle(after.theta - before.theta) > 0.5 * profile.search_angular
    # A new goal ends the search at once.
    twist = control.goal(terrain_goal(3.0, 8.0, seq=99), clock.now)
    assert twist is not None and twist.seq == 99
    assert not control.searching(clock.now)


def test_follow_stops_after_searching_for_the_goal_timeout() -> None:
    profile = PROFILES["follow"]
    control, sim, clock = follow_world()
    control.goal(terrain_goal(3.0, 8.0), clock.now)
    drive(control, sim, clock, profile.goal_timeout_s + 0.1)
    assert not control.active
    theta = sim.pose("turtle1").theta
    drive(control, sim, clock, 1.5)  # the zero Twist holds; turtlesim's own timeout too
    assert sim.pose("turtle1").theta == pytest.approx(theta, abs=1e-9)


def test_wall_clearance_along_and_against_the_heading() -> None:
    size = TurtleSim.WORLD_SIZE
    assert wall_clearance(Pose(3.0, 5.0, 0.0), forward=True) == pytest.approx(size - 3.0)
    assert wall_clearance(Pose(3.0, 5.0, 0.0), forward=False) == pytest.approx(3.0)
    assert wall_clearance(Pose(3.0, 5.0, math.pi / 2), forward=True) == pytest.approx(size - 5.0)
    diagonal = wall_clearance(Pose(1.0, 1.0, -3 * math.pi / 4), forward=True)
    assert diagonal == pytest.approx(math.sqrt(2.0))
