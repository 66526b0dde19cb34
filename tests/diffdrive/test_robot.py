"""The differential-drive robot: arcs, the command timeout and the walls, with injected time."""

from __future__ import annotations

import math

import pytest

from app.diffdrive.robot import DiffDrive

TICK = 0.016


class Clock:
    """A clock the test moves by hand."""

    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


def drive(robot: DiffDrive, clock: Clock, seconds: float) -> None:
    """Step the robot for ``seconds``, moving the clock along."""
    for _ in range(round(seconds / TICK)):
        clock.now += TICK
        robot.step()


@pytest.fixture
def clock() -> Clock:
    return Clock()


def robot_at(clock: Clock, x: float = 4.0, y: float = 3.0, yaw: float = 0.0) -> DiffDrive:
    return DiffDrive(8.0, 6.0, x, y, yaw, clock)


def test_drives_straight_along_its_heading(clock: Clock) -> None:
    robot = robot_at(clock, yaw=math.pi / 2)
    robot.cmd_vel(0.5, 0.0)
    drive(robot, clock, 0.8)  # 50 ticks of 16 ms
    state = robot.state()
    assert (state.x, state.y) == pytest.approx((4.0, 3.0 + 0.5 * 0.8))
    assert state.yaw == pytest.approx(math.pi / 2)
    assert (state.linear, state.angular) == (0.5, 0.0)


def test_a_turn_and_a_speed_drive_a_circle_of_radius_v_over_w(clock: Clock) -> None:
    robot = robot_at(clock, x=4.0, y=2.0)
    robot.cmd_vel(0.5, 0.5)  # a 1 m radius, centred 1 m to the robot's left: (4, 3)
    quarter = (math.pi / 2) / 0.5
    clock_steps = round(quarter / TICK)
    for _ in range(clock_steps):
        clock.now += TICK
        robot.step()
        robot.cmd_vel(0.5, 0.5)  # held on, as a driver repeats it
    state = robot.state()
    turned = clock_steps * TICK * 0.5
    # On the circle, exactly: each tick follows the arc, not its chord.
    assert math.hypot(state.x - 4.0, state.y - 3.0) == pytest.approx(1.0, abs=1e-9)
    assert state.yaw == pytest.approx(turned)
    assert (state.x, state.y) == pytest.approx((4.0 + math.sin(turned), 3.0 - math.cos(turned)))


def test_turning_in_place_does_not_move_it(clock: Clock) -> None:
    robot = robot_at(clock)
    robot.cmd_vel(0.0, -1.0)
    drive(robot, clock, 0.48)
    state = robot.state()
    assert (state.x, state.y) == (4.0, 3.0)
    assert state.yaw == pytest.approx(-0.48)


def test_heading_stays_within_minus_pi_and_pi(clock: Clock) -> None:
    robot = robot_at(clock, yaw=3.1)
    robot.cmd_vel(0.0, 1.0)
    drive(robot, clock, 0.16)
    assert robot.state().yaw == pytest.approx(3.1 + 0.16 - 2 * math.pi)


def test_stops_one_second_after_the_last_command(clock: Clock) -> None:
    robot = robot_at(clock, x=2.0)
    robot.cmd_vel(1.0, 0.0)
    drive(robot, clock, 0.992)  # 62 ticks: still within the second
    assert robot.state().linear == 1.0
    assert robot.state().x == pytest.approx(2.0 + 0.992)
    drive(robot, clock, 0.016)  # the first tick past the second: stopped where it was
    assert robot.state().linear == 0.0
    assert robot.state().x == pytest.approx(2.0 + 0.992)
    drive(robot, clock, 0.5)
    assert robot.state().x == pytest.approx(2.0 + 0.992)


def test_a_new_command_restarts_the_timeout(clock: Clock) -> None:
    robot = robot_at(clock, x=1.0)
    for _ in range(3):
        robot.cmd_vel(0.5, 0.0)
        drive(robot, clock, 0.8)
    assert robot.state().linear == 0.5
    assert robot.state().x == pytest.approx(1.0 + 0.5 * 2.4)


def test_the_walls_stop_it_a_radius_short(clock: Clock) -> None:
    robot = robot_at(clock, x=7.0, y=3.0)
    robot.cmd_vel(1.0, 0.0)
    drive(robot, clock, 0.8)
    assert robot.state().x == pytest.approx(8.0 - DiffDrive.RADIUS_M)
    robot.cmd_vel(-1.0, 0.0)  # and it backs away from the wall at once
    drive(robot, clock, 0.16)
    assert robot.state().x == pytest.approx(8.0 - DiffDrive.RADIUS_M - 0.16)


def test_driven_into_a_wall_at_a_slant_it_slides_along_it(clock: Clock) -> None:
    robot = robot_at(clock, x=4.0, y=5.7, yaw=math.pi / 4)
    robot.cmd_vel(1.0, 0.0)
    drive(robot, clock, 0.8)
    state = robot.state()
    assert state.y == pytest.approx(6.0 - DiffDrive.RADIUS_M)
    assert state.x == pytest.approx(4.0 + 0.8 * math.cos(math.pi / 4))


def test_no_wall_is_passed_whatever_the_speed(clock: Clock) -> None:
    robot = robot_at(clock)
    robot.cmd_vel(1e9, 0.3)
    drive(robot, clock, 2.0)
    state = robot.state()
    assert DiffDrive.RADIUS_M <= state.x <= 8.0 - DiffDrive.RADIUS_M
    assert DiffDrive.RADIUS_M <= state.y <= 6.0 - DiffDrive.RADIUS_M


def test_a_start_outside_the_room_is_brought_inside(clock: Clock) -> None:
    state = DiffDrive(8.0, 6.0, -3.0, 9.0, 0.0, clock).state()
    assert (state.x, state.y) == (DiffDrive.RADIUS_M, 6.0 - DiffDrive.RADIUS_M)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_velocity_that_is_not_finite_is_refused_and_changes_nothing(
    clock: Clock, bad: float
) -> None:
    robot = robot_at(clock)
    robot.cmd_vel(0.3, 0.2)
    with pytest.raises(ValueError, match="finite"):
        robot.cmd_vel(bad, 0.0)
    with pytest.raises(ValueError, match="finite"):
        robot.cmd_vel(0.0, bad)
    assert (robot.state().linear, robot.state().angular) == (0.3, 0.2)


def test_the_step_is_a_fixed_tick_whatever_the_wall_time(clock: Clock) -> None:
    robot = robot_at(clock)
    robot.cmd_vel(0.25, 0.0)
    clock.now += 0.5  # a late tick still moves one tick's worth
    robot.step()
    assert robot.state().x == pytest.approx(4.0 + 0.25 * TICK)


@pytest.mark.parametrize(("linear", "angular"), [(5.0, 10.0), (-5.0, -10.0)])
def test_speeds_are_capped_at_the_robots_top_speeds(
    clock: Clock, linear: float, angular: float
) -> None:
    """The diffdrive description's top speeds: 1 m/s and 3 rad/s, either way."""
    robot = robot_at(clock)
    robot.cmd_vel(linear, angular)
    state = robot.state()
    assert (state.linear, state.angular) == (
        math.copysign(1.0, linear),
        math.copysign(3.0, angular),
    )
    robot.cmd_vel(0.0, 0.0)
    drive(robot, clock, 0.5)
    robot.cmd_vel(linear, 0.0)
    drive(robot, clock, 0.48)  # 30 ticks
    assert robot.state().x == pytest.approx(4.0 + math.copysign(0.48, linear))
