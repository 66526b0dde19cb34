"""The vehicle's pilot (vehicle_agent/pilot.py): its rules, stated with their numbers, and the
shared sequences that pilot.js must answer alike (e2e/test_pilot_js.py)."""

from __future__ import annotations

import json
from typing import Any

import pytest

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.control import PROFILES, TERRAIN_CENTRE
from tests.vehicle_agent import pilot_sequences
from tests.vehicle_agent.pilot_sequences import SEQUENCES, goal
from vehicle_agent.control import Goal, Pose, Profile
from vehicle_agent.pilot import Pilot

DEFAULT = PROFILES["default"]
CENTRE = Pose(TERRAIN_CENTRE, TERRAIN_CENTRE, 0.0)


def goal_message(seq: int, t: float, late_s: float = 0.0) -> channels.Goal:
    """The relay's goal ``seq`` received at ``t`` (a face up and to the left)."""
    return channels.Goal.model_validate(goal(seq, t, late_s=late_s)[2][0])


def steering(profile: Profile = DEFAULT) -> Pilot:
    """A pilot with a pose, steering by goal 1 received at 0.0."""
    pilot = Pilot(profile)
    pilot.pose(CENTRE, 0.0)
    assert _moving(pilot.goal(goal_message(1, 0.0), 0.0))
    return pilot


def _twists(events: list[Any]) -> list[ev.TwistSent]:
    return ev.of_kind(events, ev.TwistSent)


def _moving(events: list[Any]) -> bool:
    return any(t.linear or t.angular for t in _twists(events))


def _stops(events: list[Any]) -> bool:
    twists = _twists(events)
    return bool(twists) and (twists[-1].linear, twists[-1].angular) == (0.0, 0.0)


def _run_ticks(pilot: Pilot, start: float, until: float) -> tuple[float, list[Any]] | None:
    """Tick ``pilot`` when it asks to be ticked, from ``start``; the time and answer of the
    first tick that stops the turtle, None if none does by ``until``."""
    now = start
    for _ in range(10_000):  # a clock that the wake-ups do not move on would never end
        now += max(pilot.next_tick(now), 1e-6)
        if now > until:
            break
        answer = pilot.tick(now)
        if _stops(answer):
            return now, answer
    return None


def test_a_goal_is_recorded_and_steers_the_turtle_toward_it() -> None:
    pilot = Pilot(DEFAULT)
    pilot.pose(CENTRE, 0.0)
    answer = pilot.goal(goal_message(1, 0.0), 0.0)
    applied, twist = answer
    assert isinstance(applied, ev.GoalApplied) and (applied.seq, applied.frame) == (1, 101)
    # Up and to the left of the centre: the turtle turns left (counter-clockwise).
    assert isinstance(twist, ev.TwistSent) and twist.angular > 0 and twist.seq == 1
    assert twist.t == applied.t == 0.0  # the time given, not a clock read inside


def test_goals_while_manual_are_dropped_why_manual_and_never_steer() -> None:
    pilot = steering()
    taken = pilot.mode_change("manual", "ann", 0.1)
    assert isinstance(taken[0], ev.ModeChanged) and taken[0].operator == "ann"
    assert _stops(taken)
    for seq, t in ((2, 0.2), (3, 0.3), (4, 0.4)):
        answer = pilot.goal(goal_message(seq, t), t)
        assert answer == [ev.GoalDropped(seq=seq, frame=100 + seq, why="manual", t=t)]
        assert not _twists(pilot.pose(CENTRE, t + 0.05))
        assert not _twists(pilot.tick(t + 0.06))
    # Nor after the hand-back: a goal must come again.
    pilot.mode_change("auto", None, 0.5)
    assert not _twists(pilot.pose(CENTRE, 0.6))
    assert _moving(pilot.goal(goal_message(5, 0.7), 0.7))


def test_old_and_stale_goals_are_dropped_with_their_reason() -> None:
    pilot = steering()
    assert pilot.goal(goal_message(1, 0.1), 0.1) == [
        ev.GoalDropped(seq=1, frame=101, why="old", t=0.1)
    ]
    # Half a second longer on the way than the quickest recent goal is stale; less is not.
    late = pilot.goal(goal_message(2, 0.2, late_s=0.6), 0.2)
    assert late == [ev.GoalDropped(seq=2, frame=102, why="stale", t=0.2)]
    assert isinstance(pilot.goal(goal_message(3, 0.3, late_s=0.4), 0.3)[0], ev.GoalApplied)


def test_the_dead_man_stops_within_0_3_s_of_the_last_drive_command() -> None:
    pilot = Pilot(DEFAULT)
    pilot.mode_change("manual", "ann", 0.0)
    moving = pilot.drive(1, 1.0, 0.0, 1.0)
    assert moving[0] == ev.DriveReceived(seq=1, applied=True, moving=True, t=1.0)
    assert _moving(moving)
    stopped = _run_ticks(pilot, 1.0, 5.0)
    assert stopped is not None, "the dead-man never stopped the turtle"
    at, _ = stopped
    assert at - 1.0 <= 0.3 + 1e-9
    # A live operator's repeats (every 0.1 s) never trip it.
    pilot.drive(2, 1.0, 0.0, 2.0)
    for k in range(1, 20):
        assert not _stops(pilot.tick(2.0 + 0.1 * k - 0.01))
        pilot.drive(2 + k, 1.0, 0.0, 2.0 + 0.1 * k)


def test_the_goal_timeout_stops_within_0_75_s_of_the_last_goal() -> None:
    pilot = steering()
    stopped = _run_ticks(pilot, 0.0, 5.0)
    assert stopped is not None, "the goal timeout never stopped the turtle"
    at, answer = stopped
    assert at <= 0.75
    assert _twists(answer)[-1].seq is None
    # Exactly one stop: nothing more until the next goal.
    assert not _twists(pilot.tick(at + 1.0)) and not _twists(pilot.pose(CENTRE, at + 1.1))


def test_a_lost_link_halts_the_turtle_in_either_mode() -> None:
    pilot = steering()
    assert _stops(pilot.halt(0.1))
    assert pilot.halt(0.2) == []  # already still: nothing to send
    pilot.mode_change("manual", "bob", 0.3)
    assert _moving(pilot.drive(1, 0.0, 1.0, 0.35))
    halted = pilot.halt(0.4)
    assert _stops(halted)
    # Back in auto, and it is recorded.
    assert halted[0] == ev.ModeChanged(mode="auto", operator=None, t=0.4)
    assert pilot.mode == "auto" and pilot.operator is None
    assert not _twists(pilot.drive(2, 0.0, 1.0, 0.45))


def test_a_new_link_halts_and_numbers_goals_and_drive_commands_afresh() -> None:
    pilot = steering()
    assert _moving(pilot.goal(goal_message(9, 0.1), 0.1))
    assert pilot.goal_age(0.3) == pytest.approx(0.2)
    assert _stops(pilot.new_link(0.4))
    assert pilot.goal_age(0.5) is None
    assert _moving(pilot.goal(goal_message(1, 0.6), 0.6))  # seq 1 again: a new relay


def test_the_next_tick_comes_when_a_stop_falls_due() -> None:
    pilot = Pilot(DEFAULT)
    assert pilot.next_tick(0.0) == pytest.approx(0.05)  # the regular tick
    pilot.pose(CENTRE, 0.0)
    pilot.goal(goal_message(1, 0.0), 0.0)
    assert pilot.next_tick(0.69) == pytest.approx(0.01)  # the goal timeout, sooner
    pilot.mode_change("manual", "ann", 0.8)
    pilot.drive(1, 1.0, 0.0, 1.0)
    assert pilot.next_tick(1.28) == pytest.approx(0.02)  # the dead-man, sooner


def test_a_control_law_plugs_in() -> None:
    calls: list[tuple[Goal, Pose]] = []

    def creep(goal: Goal, pose: Pose, profile: Profile) -> tuple[float, float]:
        calls.append((goal, pose))
        return 0.25, -0.5

    pilot = Pilot(DEFAULT, law=creep)
    pilot.pose(CENTRE, 0.0)
    twist = _twists(pilot.goal(goal_message(1, 0.0), 0.0))[0]
    assert (twist.linear, twist.angular) == (0.25, -0.5)
    assert calls[0][1] == CENTRE and calls[0][0].seq == 1


@pytest.mark.parametrize("robot", pilot_sequences.ROBOTS)
@pytest.mark.parametrize("profile", sorted(PROFILES))
@pytest.mark.parametrize("name", sorted(SEQUENCES))
def test_the_shared_sequences_give_records_the_event_log_reads_back(
    profile: str, name: str, robot: str
) -> None:
    answers = pilot_sequences.run(SEQUENCES[name], profile, robot)
    assert len(answers) == len(SEQUENCES[name])
    for records, next_tick, mode, _ in answers:
        for record in records:
            assert ev.record(ev.from_json(json.dumps(record))) == record
        assert 0 <= next_tick <= 0.05 and mode in ("auto", "manual")
