"""TurtleSim behaves like ROS turtlesim_node: timeout, walls, angle wrap and services."""

from __future__ import annotations

import math

import pytest

from app.turtlesim.sim import MAX_TRAIL_POINTS, Pen, TurtleSim

# turtlesim's world edge: (500 px - 1) / 45 px per metre, held in a float32.
SIZE = 11.088889122009277
CENTRE = 5.544445


class FakeClock:
    """A clock the test advances by hand."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def run(sim: TurtleSim, clock: FakeClock, seconds: float) -> None:
    """Step the sim for ``seconds`` of simulated time, moving the clock along with it."""
    for _ in range(round(seconds / 0.016)):
        clock.now += 0.016
        sim.step()


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


@pytest.fixture
def sim(clock: FakeClock) -> TurtleSim:
    return TurtleSim(clock=clock)


def test_starts_with_turtle1_at_the_centre_facing_east(sim: TurtleSim) -> None:
    assert sim.names() == ["turtle1"]
    pose = sim.pose("turtle1")
    assert (pose.x, pose.y, pose.theta) == pytest.approx((CENTRE, CENTRE, 0.0), abs=1e-6)
    assert (pose.linear_velocity, pose.angular_velocity) == (0.0, 0.0)


def test_forward_command_moves_along_heading(sim: TurtleSim, clock: FakeClock) -> None:
    sim.cmd_vel("turtle1", 1.0, 0.0)
    run(sim, clock, 0.48)  # 30 ticks
    pose = sim.pose("turtle1")
    assert pose.x == pytest.approx(CENTRE + 30 * 0.016 * 1.0)
    assert pose.y == pytest.approx(CENTRE)
    assert pose.linear_velocity == 1.0


def test_step_uses_fixed_dt_whatever_the_wall_time(sim: TurtleSim, clock: FakeClock) -> None:
    sim.cmd_vel("turtle1", 0.0, 1.0)
    clock.now += 0.5  # a late tick still advances by one 16 ms step
    sim.step()
    assert sim.pose("turtle1").theta == pytest.approx(0.016)


def test_command_expires_one_second_after_the_last(sim: TurtleSim, clock: FakeClock) -> None:
    sim.cmd_vel("turtle1", 0.0, 1.0)
    run(sim, clock, 0.96)
    turning = sim.pose("turtle1")
    assert turning.angular_velocity == 1.0
    run(sim, clock, 0.2)
    stopped = sim.pose("turtle1")
    assert stopped.angular_velocity == 0.0
    assert stopped.linear_velocity == 0.0
    # It turned for about one second at 1 rad/s, then not at all.
    assert stopped.theta == pytest.approx(1.0, abs=0.04)
    run(sim, clock, 1.0)
    assert sim.pose("turtle1").theta == stopped.theta


def test_a_new_command_extends_the_timeout(sim: TurtleSim, clock: FakeClock) -> None:
    sim.cmd_vel("turtle1", 0.0, 0.5)
    run(sim, clock, 0.8)
    sim.cmd_vel("turtle1", 0.0, 0.5)
    run(sim, clock, 0.8)
    assert sim.pose("turtle1").angular_velocity == 0.5


def test_walls_clamp_position(sim: TurtleSim, clock: FakeClock) -> None:
    sim.cmd_vel("turtle1", 10.0, 0.0)
    run(sim, clock, 0.96)
    assert sim.pose("turtle1").x == SIZE
    sim.teleport_absolute("turtle1", CENTRE, CENTRE, -math.pi / 2)
    sim.cmd_vel("turtle1", 10.0, 0.0)
    run(sim, clock, 0.96)
    pose = sim.pose("turtle1")
    assert pose.y == 0.0
    assert pose.x == pytest.approx(CENTRE)


def test_heading_wraps_into_minus_pi_to_pi(sim: TurtleSim, clock: FakeClock) -> None:
    sim.teleport_absolute("turtle1", CENTRE, CENTRE, math.pi - 0.01)
    sim.cmd_vel("turtle1", 0.0, 2.0)
    run(sim, clock, 0.016 * 3)  # +0.096 rad crosses +pi
    theta = sim.pose("turtle1").theta
    assert -math.pi <= theta < math.pi
    assert theta == pytest.approx(math.pi - 0.01 + 0.096 - 2 * math.pi)
    sim.cmd_vel("turtle1", 0.0, -2.0)
    run(sim, clock, 0.016 * 3)
    assert sim.pose("turtle1").theta == pytest.approx(math.pi - 0.01)


def test_heading_of_exactly_pi_is_reported_as_minus_pi(sim: TurtleSim) -> None:
    sim.teleport_absolute("turtle1", 1.0, 1.0, math.pi)
    sim.step()
    assert sim.pose("turtle1").theta == pytest.approx(-math.pi)


def test_teleport_absolute_sets_pose_and_clamps(sim: TurtleSim) -> None:
    # Teleports are queued and applied by the next tick, as turtlesim does.
    sim.teleport_absolute("turtle1", 2.0, 3.0, 1.0)
    sim.step()
    pose = sim.pose("turtle1")
    assert (pose.x, pose.y, pose.theta) == pytest.approx((2.0, 3.0, 1.0))
    sim.teleport_absolute("turtle1", -5.0, 50.0, 7.0)
    sim.step()
    pose = sim.pose("turtle1")
    assert (pose.x, pose.y) == (0.0, SIZE)
    assert pose.theta == pytest.approx(7.0 - 2 * math.pi)


def test_teleport_relative_turns_then_moves(sim: TurtleSim) -> None:
    sim.teleport_relative("turtle1", 2.0, math.pi / 2)
    sim.step()
    pose = sim.pose("turtle1")
    assert pose.theta == pytest.approx(math.pi / 2)
    assert (pose.x, pose.y) == pytest.approx((CENTRE, CENTRE + 2.0))
    sim.teleport_relative("turtle1", 1.0, math.pi / 2)
    sim.step()
    pose = sim.pose("turtle1")
    assert (pose.x, pose.y) == pytest.approx((CENTRE - 1.0, CENTRE + 2.0))


def test_spawn_names_and_duplicates(sim: TurtleSim) -> None:
    assert sim.spawn(1.0, 2.0, 0.5) == "turtle2"
    assert sim.spawn(3.0, 3.0, 0.0, "leo") == "leo"
    assert sim.spawn(3.0, 3.0, 0.0) == "turtle3"
    assert sim.names() == ["turtle1", "turtle2", "leo", "turtle3"]
    pose = sim.pose("turtle2")
    assert (pose.x, pose.y, pose.theta) == pytest.approx((1.0, 2.0, 0.5))
    with pytest.raises(ValueError, match="already exists"):
        sim.spawn(1.0, 1.0, 0.0, "leo")
    with pytest.raises(ValueError, match="invalid"):
        sim.spawn(1.0, 1.0, 0.0, "9/bad name")


def test_auto_name_skips_names_taken_by_hand(sim: TurtleSim) -> None:
    sim.spawn(1.0, 1.0, 0.0, "turtle2")
    assert sim.spawn(1.0, 1.0, 0.0) == "turtle3"


def test_turtles_move_independently(sim: TurtleSim, clock: FakeClock) -> None:
    sim.spawn(1.0, 1.0, math.pi / 2, "other")
    sim.cmd_vel("other", 1.0, 0.0)
    run(sim, clock, 0.48)
    assert sim.pose("other").y == pytest.approx(1.0 + 0.48)
    assert sim.pose("turtle1").x == pytest.approx(CENTRE)


def test_kill_removes_a_turtle(sim: TurtleSim) -> None:
    sim.spawn(1.0, 1.0, 0.0, "leo")
    sim.kill("turtle1")
    assert sim.names() == ["leo"]
    with pytest.raises(KeyError):
        sim.pose("turtle1")
    with pytest.raises(KeyError):
        sim.kill("turtle1")


def test_unknown_names_raise_key_error(sim: TurtleSim) -> None:
    calls = [
        lambda: sim.cmd_vel("nobody", 1.0, 0.0),
        lambda: sim.pose("nobody"),
        lambda: sim.kill("nobody"),
        lambda: sim.teleport_absolute("nobody", 1.0, 1.0, 0.0),
        lambda: sim.teleport_relative("nobody", 1.0, 0.0),
        lambda: sim.set_pen("nobody", 1, 2, 3, 1, False),
    ]
    for call in calls:
        with pytest.raises(KeyError, match="nobody"):
            call()


def test_reset_brings_back_one_turtle1_at_the_centre(sim: TurtleSim, clock: FakeClock) -> None:
    sim.spawn(1.0, 1.0, 0.0)
    sim.teleport_absolute("turtle1", 1.0, 1.0, 1.0)
    sim.cmd_vel("turtle1", 1.0, 1.0)
    sim.reset()
    assert sim.names() == ["turtle1"]
    run(sim, clock, 0.1)
    pose = sim.pose("turtle1")
    assert (pose.x, pose.y, pose.theta) == pytest.approx((CENTRE, CENTRE, 0.0))
    assert [len(s.points) for s in sim.strokes()] == [1]
    # Auto-naming starts again from turtle2.
    assert sim.spawn(1.0, 1.0, 0.0) == "turtle2"


def test_pen_trail_follows_motion_and_clear_erases_it(sim: TurtleSim, clock: FakeClock) -> None:
    sim.cmd_vel("turtle1", 1.0, 0.0)
    run(sim, clock, 0.48)
    (stroke,) = sim.strokes()
    assert stroke.turtle == "turtle1"
    assert stroke.points[0] == pytest.approx((CENTRE, CENTRE))
    assert stroke.points[-1] == pytest.approx((CENTRE + 0.48, CENTRE))
    sim.clear()
    (stroke,) = sim.strokes()
    assert stroke.points == [pytest.approx((CENTRE + 0.48, CENTRE))]
    assert sim.pose("turtle1").x == pytest.approx(CENTRE + 0.48)


def test_turning_in_place_draws_nothing(sim: TurtleSim, clock: FakeClock) -> None:
    sim.cmd_vel("turtle1", 0.0, 1.0)
    run(sim, clock, 0.5)
    assert [len(s.points) for s in sim.strokes()] == [1]


def test_set_pen_changes_colour_and_off_stops_drawing(sim: TurtleSim, clock: FakeClock) -> None:
    assert sim.pen("turtle1") == Pen()
    sim.set_pen("turtle1", 255, 0, 0, 5, False)
    assert sim.pen("turtle1") == Pen(255, 0, 0, 5, False)
    sim.teleport_absolute("turtle1", 1.0, 1.0, 0.0)
    sim.step()
    red = [s for s in sim.strokes() if s.pen.r == 255]
    assert len(red) == 1
    assert red[0].points[-1] == (1.0, 1.0)
    sim.set_pen("turtle1", 0, 0, 0, 1, True)
    # Lifting the pen keeps its colour and width, as turtlesim does.
    assert sim.pen("turtle1") == Pen(255, 0, 0, 5, True)
    before = sum(len(s.points) for s in sim.strokes())
    sim.teleport_absolute("turtle1", 3.0, 3.0, 0.0)
    sim.step()
    assert sum(len(s.points) for s in sim.strokes()) == before
    with pytest.raises(ValueError, match="0..255"):
        sim.set_pen("turtle1", 256, 0, 0, 1, False)


def test_killed_turtles_drawing_stays(sim: TurtleSim) -> None:
    sim.spawn(1.0, 1.0, 0.0, "leo")
    sim.teleport_absolute("leo", 2.0, 1.0, 0.0)
    sim.step()
    sim.kill("leo")
    assert any(s.turtle == "leo" and len(s.points) == 2 for s in sim.strokes())


def test_trail_length_is_bounded(sim: TurtleSim) -> None:
    for i in range(MAX_TRAIL_POINTS + 500):
        sim.teleport_absolute("turtle1", 1.0 + (i % 2), 1.0, 0.0)
        sim.step()
    total = sum(len(s.points) for s in sim.strokes() if s.turtle == "turtle1")
    assert total == MAX_TRAIL_POINTS
    # The oldest points went; the newest is where the turtle is now.
    pose = sim.pose("turtle1")
    assert sim.strokes()[-1].points[-1] == (pose.x, pose.y)


def test_teleports_wait_for_the_next_tick(sim: TurtleSim) -> None:
    # turtlesim queues teleport requests; its next update applies them (docs F5).
    sim.teleport_absolute("turtle1", 1.0, 1.0, 0.0)
    sim.teleport_relative("turtle1", 1.0, 0.0)
    assert (sim.pose("turtle1").x, sim.pose("turtle1").y) == pytest.approx((CENTRE, CENTRE))
    sim.step()
    assert (sim.pose("turtle1").x, sim.pose("turtle1").y) == pytest.approx((2.0, 1.0))


def test_spawn_outside_the_world_is_clamped_by_its_first_tick(sim: TurtleSim) -> None:
    sim.spawn(-2.0, 30.0, 9.0, "leo")
    assert (sim.pose("leo").x, sim.pose("leo").y, sim.pose("leo").theta) == (-2.0, 30.0, 9.0)
    sim.step()
    pose = sim.pose("leo")
    assert (pose.x, pose.y) == (0.0, SIZE)
    assert pose.theta == pytest.approx(9.0 - 2 * math.pi)


def test_sideways_command_moves_a_holonomic_turtle_and_speed_is_a_magnitude(
    sim: TurtleSim, clock: FakeClock
) -> None:
    sim.cmd_vel("turtle1", -0.6, 0.0, linear_y=0.8)
    run(sim, clock, 0.16)  # 10 ticks
    pose = sim.pose("turtle1")
    assert (pose.x, pose.y) == pytest.approx((CENTRE - 0.096, CENTRE + 0.128))
    assert pose.linear_velocity == pytest.approx(1.0)


def test_sideways_command_is_ignored_unless_holonomic(sim: TurtleSim, clock: FakeClock) -> None:
    sim.holonomic = False  # the turtlesim_msgs-era node without its ``holonomic`` parameter
    sim.cmd_vel("turtle1", 0.0, 0.0, linear_y=1.0)
    run(sim, clock, 0.16)
    assert sim.pose("turtle1").y == pytest.approx(CENTRE)
    assert sim.pose("turtle1").linear_velocity == 0.0


def test_set_pen_width_zero_means_qt_default_width(sim: TurtleSim) -> None:
    sim.set_pen("turtle1", 1, 2, 3, 0, False)
    assert sim.pen("turtle1") == Pen(1, 2, 3, 1, False)
