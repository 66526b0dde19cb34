"""The robot's limits (vehicle_agent/core/limits.py, inside the pilot): every command clamped to the
top speeds and ramped within the accelerations, a stop at once. Stated with the TurtleBot3
Burger's numbers: 0.22 m/s, 2.84 rad/s, 2.5 m/s², 3.2 rad/s²."""

from __future__ import annotations

import math
import random
from dataclasses import replace
from typing import Any

import pytest

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.control import PROFILES, TERRAIN_CENTRE
from app.protocol.robot import PRESETS, Limits
from tests.vehicle_agent.core.pilot_sequences import goal
from vehicle_agent.core.control import Pose, Twist
from vehicle_agent.core.limits import Limiter
from vehicle_agent.core.pilot import Pilot

BURGER = PRESETS["turtlebot3"]
TICK_S = 0.05
CENTRE = Pose(TERRAIN_CENTRE, TERRAIN_CENTRE, 0.0)


def burger_pilot(profile: str = "default") -> Pilot:
    """A pilot for a Burger, as the agent builds it."""
    return Pilot(PROFILES[profile], robot=BURGER)


def twists(events: list[Any]) -> list[ev.TwistSent]:
    return ev.of_kind(events, ev.TwistSent)


def assert_within_the_burgers_limits(sent: list[ev.TwistSent]) -> None:
    """Top speeds, and the change between consecutive Twists (a stop excepted)."""
    for twist in sent:
        assert abs(twist.linear) <= 0.22 + 1e-12, twist
        assert abs(twist.angular) <= 2.84 + 1e-12, twist
    for before, after in zip(sent, sent[1:], strict=False):
        if after.linear == after.angular == 0.0 and after.seq is None:
            continue  # a stop goes out at once
        dt = after.t - before.t
        assert abs(after.linear - before.linear) <= 2.5 * dt + 1e-9, (before, after)
        assert abs(after.angular - before.angular) <= 3.2 * dt + 1e-9, (before, after)


def test_whatever_the_command_a_burger_never_exceeds_its_limits() -> None:
    limiter = Limiter(BURGER.limits, TICK_S)
    draw = random.Random(36)
    out: list[ev.TwistSent] = []
    now = 0.0
    for _ in range(2000):
        now += draw.choice((0.0, 0.001, 0.02, 0.05, 0.3, 5.0))
        if draw.random() < 0.3:
            twist = limiter.tick(now)
        else:
            command = Twist(draw.uniform(-50, 50), draw.uniform(-50, 50), seq=1)
            twist = limiter.command(command, now)
        if twist is not None:
            out.append(
                ev.TwistSent(
                    seq=twist.seq, frame=None, linear=twist.linear_x, angular=twist.angular_z, t=now
                )
            )
    assert len(out) > 1000
    assert_within_the_burgers_limits(out)


def test_a_command_out_of_reach_is_ramped_to_on_the_ticks() -> None:
    limiter = Limiter(BURGER.limits, TICK_S)
    first = limiter.command(Twist(1.0, -10.0, seq=7), 0.0)
    # The first step from rest counts one tick: 2.5 m/s² and 3.2 rad/s² times 0.05 s.
    assert (first.linear_x, first.angular_z) == pytest.approx((0.125, -0.16))
    assert first.seq == 7
    steps = [first]
    now = 0.0
    while (step := limiter.tick(now + TICK_S)) is not None:
        now += TICK_S
        steps.append(step)
    # Full speed at 0.22 m/s after 0.22 / 2.5 s, full turn at 2.84 rad/s after 2.84 / 3.2 s.
    assert (steps[-1].linear_x, steps[-1].angular_z) == (0.22, -2.84)
    assert now == pytest.approx(0.9, abs=TICK_S)
    assert steps[2].linear_x == 0.22 and steps[1].linear_x == pytest.approx(0.22)
    assert limiter.tick(now + 1.0) is None  # reached: nothing more to publish


def test_a_robot_at_rest_does_not_jump_to_full_speed() -> None:
    limiter = Limiter(BURGER.limits, TICK_S)
    limiter.command(Twist(0.0, 0.0), 0.0)
    # A minute later: still one tick's worth of acceleration, not sixty seconds' worth.
    moving = limiter.command(Twist(0.22, 0.0, seq=1), 60.0)
    assert moving.linear_x == pytest.approx(2.5 * 0.05)


@pytest.mark.parametrize("how", ["stop", "halt", "mode", "released stick", "dead-man"])
def test_a_stop_goes_out_at_once_whatever_the_speed(how: str) -> None:
    pilot = burger_pilot()
    sent: list[ev.TwistSent] = []
    if how in ("released stick", "dead-man"):
        pilot.mode_change("manual", "ann", 0.0)
        for k in range(10):  # the operator holds the stick, repeating every 0.1 s
            sent += twists(pilot.drive(1 + k, 1.0, 1.0, 0.1 * k))
            sent += twists(pilot.tick(0.1 * k + 0.05))
        # Full stick on a Burger: its top speed ahead, turtlesim's 2 rad/s turn (below 2.84).
        assert (sent[-1].linear, sent[-1].angular) == pytest.approx((0.22, 2.0))
    else:
        pilot.pose(CENTRE, 0.0)
        for k in range(19):
            if k % 4 == 0:  # a face at the frame's bottom-left corner, every 0.2 s
                message = goal(k // 4 + 1, 0.05 * k, x=0.0, y=470.0)[2][0]
                sent += twists(pilot.goal(channels.Goal.model_validate(message), 0.05 * k))
            sent += twists(pilot.pose(CENTRE, 0.05 * k + 0.01))
            sent += twists(pilot.tick(0.05 * k + 0.03))
        # Turning at the Burger's top rate when the stop comes.
        assert abs(sent[-1].angular) == pytest.approx(2.84)
    at = 0.95
    match how:
        case "stop":
            answer = pilot.stop(at)
        case "halt":
            answer = pilot.halt(at)
        case "mode":
            answer = pilot.mode_change("manual", "bob", at)
        case "released stick":
            answer = pilot.drive(100, 0.0, 0.0, at)
        case _:
            answer = []
            now = 0.95
            while not twists(answer) or twists(answer)[-1].angular != 0.0:
                now += max(pilot.next_tick(now), 1e-6)
                answer = pilot.tick(now)
            # The dead-man's contract: stopped within 0.3 s of the last command (at 0.9 s).
            assert now - 0.9 <= 0.3 + 1e-5
    last = twists(answer)[-1]
    assert (last.linear, last.angular) == (0.0, 0.0)


def test_the_autopilot_on_a_burger_stays_within_its_limits() -> None:
    for profile in ("default", "thesis", "follow"):
        pilot = burger_pilot(profile)
        sent: list[ev.TwistSent] = []
        now = 0.0
        pose = Pose(TERRAIN_CENTRE, TERRAIN_CENTRE, 1.0)
        for k in range(300):
            now = 0.02 * k
            if k % 10 == 0:  # goals at 5 Hz, far to one side then the other every 3 s
                x = 0.0 if (k // 150) % 2 else 640.0
                message = goal(k // 10 + 1, now, x=x, y=470.0)[2][0]
                sent += twists(pilot.goal(channels.Goal.model_validate(message), now))
            sent += twists(pilot.pose(pose, now + 0.005))
            sent += twists(pilot.tick(now + 0.01))
        assert len(sent) > 20, profile
        assert_within_the_burgers_limits(sent)
        # It does turn: the limit is reached, not merely never approached.
        assert max(abs(t.angular) for t in sent) == pytest.approx(2.84), profile


def test_an_operators_full_stick_is_the_robots_top_speed() -> None:
    pilot = burger_pilot()
    pilot.mode_change("manual", "ann", 0.0)
    sent: list[ev.TwistSent] = []
    for k in range(30):
        sent += twists(pilot.drive(k + 1, 0.5, -1.0, 0.1 * k))
        sent += twists(pilot.tick(0.1 * k + 0.05))
    assert_within_the_burgers_limits(sent)
    # Half the stick is half the robot's top speed, not half of turtlesim's 1.5 m/s clamped;
    # a full turn is the operator's 2 rad/s, which the Burger's 2.84 rad/s allows.
    assert (sent[-1].linear, sent[-1].angular) == pytest.approx((0.11, -2.0))


def test_turtlesim_commands_pass_unchanged() -> None:
    # The default robot: full stick is 1.5 m/s and 2 rad/s at once, as it always was.
    pilot = Pilot(PROFILES["default"])
    pilot.mode_change("manual", "ann", 0.0)
    sent = twists(pilot.drive(1, 1.0, -1.0, 0.1))
    assert [(t.linear, t.angular) for t in sent] == [(1.5, -2.0)]
    assert twists(pilot.tick(0.15)) == []


def test_unlimited_accelerations_take_the_command_exactly() -> None:
    limiter = Limiter(Limits(4.0, 5.0, float("inf"), float("inf")), TICK_S)
    limiter.command(Twist(0.1, 0.1, seq=1), 0.0)
    # No rounding on the way: 0.1 + (0.3 - 0.1) would be 0.30000000000000004.
    assert limiter.command(Twist(0.3, 4.9, seq=2), 0.0) == Twist(0.3, 4.9, seq=2)
    assert limiter.command(Twist(9.0, -9.0, seq=3), 1.0) == Twist(4.0, -5.0, seq=3)


def test_a_command_reaches_only_the_share_of_the_top_speed_it_names() -> None:
    limiter = Limiter(Limits(0.22, 2.84, math.inf, math.inf), TICK_S)
    # Half the Burger's top speed, ahead and back; below it, what was asked; without a share,
    # the whole of it.
    assert limiter.command(Twist(5.0, 0.0, seq=1, top_share=0.5), 0.0).linear_x == 0.11
    assert limiter.command(Twist(-5.0, 0.0, seq=2, top_share=0.5), 0.1).linear_x == -0.11
    assert limiter.command(Twist(0.05, 0.0, seq=3, top_share=0.5), 0.2).linear_x == 0.05
    assert limiter.command(Twist(5.0, 0.0, seq=4), 0.3).linear_x == 0.22
    # No share of no top speed is still nothing (not the NaN of inf · 0).
    unlimited = Limiter(Limits(math.inf, math.inf, math.inf, math.inf), TICK_S)
    assert unlimited.command(Twist(5.0, 1.0, seq=5, top_share=0.0), 0.0) == Twist(0.0, 1.0, seq=5)


def test_the_follow_law_off_to_one_side_gets_that_share_of_the_robots_top_speed() -> None:
    """The law drives as much as it faces its target: 60° off, half the Burger's top speed,
    however fast the distance asks it to go (3 m/s here: 3 (m/s)/m, 2 m beyond the standoff)."""
    burger = replace(BURGER, limits=replace(BURGER.limits, linear_accel=math.inf))
    pilot = Pilot(PROFILES["follow"], robot=burger)
    pilot.pose(CENTRE, 0.0)
    tx = TERRAIN_CENTRE + 3.0 * math.cos(math.pi / 3)
    ty = TERRAIN_CENTRE + 3.0 * math.sin(math.pi / 3)
    message = goal(1, 0.0, x=tx * 320 / TERRAIN_CENTRE, y=480 - ty * 240 / TERRAIN_CENTRE)[2][0]
    (sent,) = twists(pilot.goal(channels.Goal.model_validate(message), 0.0))
    assert sent.linear == pytest.approx(0.22 * 0.5, abs=1e-12)
