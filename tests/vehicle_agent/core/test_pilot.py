"""The vehicle's pilot (vehicle_agent/core/pilot.py): its rules, stated with their numbers, and the
shared sequences that pilot.js must answer alike (e2e/test_pilot_js.py)."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from typing import Any

import pytest

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.control import PROFILES, TERRAIN_CENTRE
from app.protocol.robot import PRESETS
from tests.vehicle_agent.core import pilot_sequences
from tests.vehicle_agent.core.pilot_sequences import SEQUENCES, goal
from vehicle_agent.core.control import Goal, Pose, Profile, Twist, pixel_bearing, target_range
from vehicle_agent.core.pilot import Pilot

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


def test_a_goal_is_recorded_locked_only_when_its_relay_says_so() -> None:
    pilot = Pilot(DEFAULT)
    for seq, locked in ((1, None), (2, True), (3, False)):
        message = channels.Goal.model_validate(goal(seq, seq / 10, locked=locked)[2][0])
        applied = ev.of_kind(pilot.goal(message, seq / 10), ev.GoalApplied)
        assert [a.locked for a in applied] == [locked is True], seq


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


def test_goals_from_the_future_are_dropped_and_never_hold_back_the_real_ones() -> None:
    pilot = steering()
    far = channels.Goal.model_validate(goal(2**40, 0.1)[2][0])
    assert pilot.goal(far, 0.1) == [
        ev.GoalDropped(seq=2**40, frame=100 + 2**40, why="future", t=0.1)
    ]
    ahead = goal(2, 0.15, stamp_ms=pilot_sequences.FAR_FUTURE_MS)[2][0]
    dropped = pilot.goal(channels.Goal.model_validate(ahead), 0.15)
    assert dropped == [ev.GoalDropped(seq=2, frame=102, why="future", t=0.15)]
    for seq in (2, 3, 4):
        assert isinstance(pilot.goal(goal_message(seq, seq * 0.1), seq * 0.1)[0], ev.GoalApplied)


def test_a_seq_past_what_a_page_can_count_is_no_goal() -> None:
    with pytest.raises(ValueError, match="seq"):
        channels.Goal.model_validate(goal(channels.GOAL_SEQ_MAX + 1, 0.1)[2][0])


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

    def creep(goal: Goal, pose: Pose, profile: Profile) -> Twist:
        calls.append((goal, pose))
        return Twist(0.25, -0.5)

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
    for records, next_tick, mode, _, search in answers:
        for record in records:
            assert ev.record(ev.from_json(json.dumps(record))) == record
        assert 0 <= next_tick <= 0.05 and mode in ("auto", "manual")
        # What the pose tells the client is a value the wire accepts.
        channels.Pose(x=1.0, y=2.0, theta=0.0, search=search)


# --- the onboard law: a camera the vehicle carries --------------------------------------------

# The diffdrive robot's camera: 60° across a 640-pixel frame, so f = 320 / tan 30° = 554.26 px.
# The law and the top speeds alone: the diffdrive robot (its camera, 1 m/s and 3 rad/s) without
# its ramp.
DIFFDRIVE = PRESETS["diffdrive"]
CAMERA_ONLY = replace(
    DIFFDRIVE, limits=replace(DIFFDRIVE.limits, linear_accel=math.inf, angular_accel=math.inf)
)
ODOM = Pose(1.0, 3.0, 0.0)
FOCAL_PX = 320 / math.tan(math.radians(30))


def face(seq: int, t: float, x: float, range_m: float | None = None) -> channels.Goal:
    """A face at column ``x`` of a 640×480 frame, its box as high as a 0.24 m face ``range_m``
    away looks (no box when None)."""
    message = goal(seq, t, x=x, y=240.0)[2][0]
    if range_m is not None:
        box_h = FOCAL_PX * 0.24 / range_m
        message |= {"boxW": box_h, "boxH": box_h, "targetHeightM": 0.24}
    return channels.Goal.model_validate(message)


def onboard(pose: Pose = ODOM) -> Pilot:
    pilot = Pilot(PROFILES["onboard"], robot=CAMERA_ONLY)
    pilot.pose(pose, 0.0)
    return pilot


def _command(pilot: Pilot, goal_: channels.Goal, t: float) -> ev.TwistSent:
    twists = _twists(pilot.goal(goal_, t))
    assert twists, "the goal was not answered"
    return twists[-1]


def test_the_bearing_is_positive_to_the_left_and_half_the_field_of_view_at_the_edge() -> None:
    hfov = math.radians(60)
    assert pixel_bearing(320, 640, hfov) == 0.0
    # A target right of the image centre has a negative bearing (θ is counter-clockwise).
    assert math.degrees(pixel_bearing(480, 640, hfov)) == pytest.approx(-16.10, abs=0.01)
    assert math.degrees(pixel_bearing(160, 640, hfov)) == pytest.approx(16.10, abs=0.01)
    assert math.degrees(pixel_bearing(640, 640, hfov)) == pytest.approx(-30.0)
    assert math.degrees(pixel_bearing(0, 640, hfov)) == pytest.approx(30.0)


def test_the_range_is_the_focal_length_times_the_real_height_over_the_box_height() -> None:
    hfov = math.radians(60)
    # A 0.24 m face 110.85 px high through a 554.26 px focal length is 1.2 m away.
    assert target_range(110.85, 0.24, 640, hfov) == pytest.approx(1.2, abs=1e-3)
    assert target_range(55.43, 0.24, 640, hfov) == pytest.approx(2.4, abs=1e-3)


def test_a_face_right_of_centre_turns_the_robot_clockwise_and_left_of_it_counter() -> None:
    assert _command(onboard(), face(1, 0.0, x=500.0), 0.0).angular < 0
    assert _command(onboard(), face(1, 0.0, x=140.0), 0.0).angular > 0


def test_a_face_within_about_a_degree_of_centre_is_not_turned_to() -> None:
    # 10 px off centre is 1.03°: inside the dead band; 25 px (2.6°) is outside it.
    assert _command(onboard(), face(1, 0.0, x=330.0), 0.0).angular == 0.0
    assert _command(onboard(), face(1, 0.0, x=310.0), 0.0).angular == 0.0
    assert _command(onboard(), face(1, 0.0, x=345.0), 0.0).angular < 0
    assert _command(onboard(), face(1, 0.0, x=295.0), 0.0).angular > 0


def test_turning_is_bounded() -> None:
    edge = _command(onboard(), face(1, 0.0, x=0.0), 0.0)
    assert 0 < edge.angular <= 2.5


def test_the_turn_since_the_goal_is_taken_off_its_bearing() -> None:
    # A face 16° to the right; once the robot has turned 16° right the command is no turn.
    pilot = onboard()
    assert _command(pilot, face(1, 0.0, x=480.0), 0.0).angular < 0
    turned = _twists(pilot.pose(Pose(1.0, 3.0, math.radians(-16.10)), 0.06))
    assert turned and turned[-1].angular == 0.0


def test_the_bearing_is_taken_from_the_heading_the_frame_was_taken_at() -> None:
    # A face 16.10° to the right in a frame taken at 0.0; by the time its goal arrives (0.15)
    # the robot has turned 0.2 rad (11.46°) right: 4.64° are left to turn, at 4 (rad/s)/rad.
    def turned_pilot() -> Pilot:
        pilot = onboard(Pose(1.0, 3.0, 0.0))
        pilot.pose(Pose(1.0, 3.0, -0.1), 0.05)
        pilot.pose(Pose(1.0, 3.0, -0.2), 0.1)
        return pilot

    pilot = turned_pilot()
    pilot.frame(101, 0.0)  # the goal's frame (goal 1 names frame 101)
    twist = _twists(pilot.goal(face(1, 0.15, x=480.0), 0.15))[-1]
    assert twist.angular == pytest.approx(4.0 * math.radians(-16.10 + 11.46), abs=1e-3)
    # Taken at 0.07: the heading then was the pose of 0.05's, −0.1 rad (5.73°).
    pilot = turned_pilot()
    pilot.frame(101, 0.07)
    twist = _twists(pilot.goal(face(1, 0.15, x=480.0), 0.15))[-1]
    assert twist.angular == pytest.approx(4.0 * math.radians(-16.10 + 5.73), abs=1e-3)
    # Not known (another frame's time is): the heading on arrival, the whole 16.10° to turn.
    pilot = turned_pilot()
    pilot.frame(100, 0.0)
    twist = _twists(pilot.goal(face(1, 0.15, x=480.0), 0.15))[-1]
    assert twist.angular == pytest.approx(4.0 * math.radians(-16.10), abs=1e-3)


def test_the_standoff_is_held_far_drives_near_backs_off() -> None:
    far = _command(onboard(), face(1, 0.0, x=320.0, range_m=3.0), 0.0)
    assert far.linear > 0 and far.angular == 0.0
    at_standoff = _command(onboard(), face(1, 0.0, x=320.0, range_m=1.2), 0.0)
    assert at_standoff.linear == pytest.approx(0.0, abs=1e-9)
    near = _command(onboard(), face(1, 0.0, x=320.0, range_m=0.6), 0.0)
    assert near.linear < 0
    # 0.2 m too far: 2.5 (m/s)/m, so that a walker at 0.6 m/s is trailed 0.24 m beyond the
    # standoff, not 0.6 m.
    a_little_far = _command(onboard(), face(1, 0.0, x=320.0, range_m=1.4), 0.0)
    assert a_little_far.linear == pytest.approx(0.5, abs=1e-6)
    # Bounded both ways by the robot's top speed, 1 m/s (the law asks for 2.5 · (20 − 1.2) m/s).
    assert _command(onboard(), face(1, 0.0, x=320.0, range_m=20.0), 0.0).linear == 1.0
    assert _command(onboard(), face(1, 0.0, x=320.0, range_m=0.2), 0.0).linear == -1.0


def test_forward_speed_falls_as_the_bearing_grows_and_stops_well_off_it() -> None:
    speeds = [
        _command(onboard(), face(1, 0.0, x=x, range_m=3.0), 0.0).linear
        for x in (320.0, 400.0, 480.0, 560.0, 640.0)
    ]
    assert speeds[0] > speeds[1] > speeds[2] > speeds[3] >= 0
    # At the frame's edge (30° off) the robot turns first.
    assert speeds[4] == 0.0


def test_without_a_box_the_robot_only_turns() -> None:
    twist = _command(onboard(), face(1, 0.0, x=500.0), 0.0)
    assert twist.linear == 0.0 and twist.angular < 0


def test_without_a_camera_the_onboard_law_never_moves_the_robot() -> None:
    pilot = Pilot(PROFILES["onboard"])  # no field of view: no bearing
    pilot.pose(ODOM, 0.0)
    assert not _moving(pilot.goal(face(1, 0.0, x=500.0, range_m=3.0), 0.0))


def _trail(target_rate: float, seconds: float = 6.0) -> list[tuple[float, float]]:
    """A robot on the diffdrive preset's limits following a face that walks round it at
    ``target_rate`` rad/s (counter-clockwise: to the left), over ``seconds``: goals about 8 a
    second, each from a frame taken 0.15 s before it arrives, and odometry every 20 ms. The
    robot turns exactly as commanded. The face's true bearing (rad) at each odometry, by time."""
    pilot = Pilot(PROFILES["onboard"], robot=PRESETS["diffdrive"])
    theta, angular = 0.0, 0.0
    headings: list[tuple[float, float]] = []
    trail: list[tuple[float, float]] = []
    seq = 0
    for k in range(round(seconds / 0.02)):
        now = 0.02 * k
        theta += angular * 0.02
        headings.append((now, theta))
        answers = pilot.pose(Pose(1.0, 3.0, theta), now)
        if k % 6 == 3 and now >= 0.15:
            seq += 1
            taken = now - 0.15
            then = next(h for t, h in reversed(headings) if t <= taken + 1e-9)
            bearing = target_rate * taken - then
            x = 320.0 - FOCAL_PX * math.tan(bearing)
            pilot.frame(100 + seq, taken)
            answers += pilot.goal(face(seq, now, x=x, range_m=1.2), now)
        answers += pilot.tick(now + 0.001)
        for twist in _twists(answers):
            angular = twist.angular
        trail.append((now, target_rate * now - theta))
    return trail


@pytest.mark.parametrize("target_rate", [0.4, -0.6])
def test_a_face_that_walks_round_the_robot_is_kept_on_the_axis(target_rate: float) -> None:
    # A walker crossing the view 1.2 m away at 0.5-0.7 m/s turns about the robot at 0.4-0.6
    # rad/s. A turn in proportion to its bearing alone would trail it by rate / gain plus what
    # it walks while its frames are on their way (0.4 / 4 + 0.4 * 0.15 rad, 9°); the law also
    # turns at the rate it is seen walking, and leads it by its frames' age: it keeps the face
    # within its dead band (1.15°) and a little.
    settled = [bearing for t, bearing in _trail(target_rate) if t >= 3.0]
    assert max(abs(math.degrees(b)) for b in settled) < 1.5


def _at_bearing(bearing: float) -> float:
    """The column of a 640-pixel frame a face ``bearing`` rad to the left is seen in."""
    return 320.0 - FOCAL_PX * math.tan(bearing)


def test_a_face_seen_walking_is_turned_with_and_a_jump_is_not_a_walk() -> None:
    # The robot still, a face seen 0.05 rad further left every 0.1 s: it walks at 0.5 rad/s.
    pilot = onboard()
    for k in range(4):
        twist = _command(pilot, face(k + 1, 0.1 * k, x=_at_bearing(0.05 * k)), 0.1 * k)
    # 0.15 rad off: 4 (rad/s)/rad toward it, and 0.5 rad/s with it.
    assert twist.angular == pytest.approx(4.0 * 0.15 + 0.5, abs=1e-6)
    # Between goals the face is led by its walk: 0.06 s on, 0.03 rad further left.
    later = _twists(pilot.pose(ODOM, 0.36))[-1]
    assert later.angular == pytest.approx(4.0 * 0.18 + 0.5, abs=1e-6)
    # 0.45 rad in 0.1 s is faster than the robot turns (2.5 rad/s): another face, not a walk.
    jumped = _command(pilot, face(5, 0.4, x=_at_bearing(-0.3)), 0.4)
    assert jumped.angular == pytest.approx(4.0 * -0.3, abs=1e-6)


def _lost_after(side_x: float) -> tuple[Pilot, list[Any]]:
    """An onboard pilot that saw a face at column ``side_x`` at 0 and nothing since, fed
    odometry every 30 ms for 10 s (the robot not turning); every answer, in order."""
    pilot = onboard()
    _command(pilot, face(1, 0.0, x=side_x, range_m=2.0), 0.0)
    answers: list[Any] = []
    for k in range(1, 334):
        now = 0.03 * k
        answers += pilot.pose(ODOM, now)
        answers += pilot.tick(now + 0.001)
    return pilot, answers


@pytest.mark.parametrize(("x", "side", "sign"), [(40.0, "left", 1), (600.0, "right", -1)])
def test_a_lost_face_is_searched_for_toward_the_side_it_was_last_seen(
    x: float, side: str, sign: int
) -> None:
    _, answers = _lost_after(x)
    started = ev.of_kind(answers, ev.SearchStarted)
    assert len(started) == 1 and started[0].side == side
    # A short gap is not a loss: it starts under half a second after the last goal.
    assert 0.2 <= started[0].t <= 0.5
    searching = [t for t in _twists(answers) if started[0].t <= t.t and t.seq is None]
    # It stops driving and turns toward that side, at a bounded rate.
    assert searching[0].linear == 0.0 and sign * searching[0].angular > 0
    assert all(abs(t.angular) <= 2.5 for t in searching)


def test_a_search_stops_after_its_bound_and_says_so() -> None:
    pilot, answers = _lost_after(600.0)
    started = ev.of_kind(answers, ev.SearchStarted)[0]
    ended = ev.of_kind(answers, ev.SearchEnded)
    assert len(ended) == 1 and ended[0].why == "timed_out"
    assert ended[0].after_s == pytest.approx(ended[0].t - started.t)
    # Bounded: stopped within 8 s of losing the face, having turned at most a turn and a half.
    assert ended[0].t <= 8.0
    searching = [t for t in _twists(answers) if started.t <= t.t < ended[0].t]
    turned = sum(abs(t.angular) * 0.03 for t in searching)
    assert turned <= 3 * math.pi + 0.2
    # Stopped, with the record first, and nothing more.
    last = _twists(answers)[-1]
    assert (last.linear, last.angular, last.t) == (0.0, 0.0, ended[0].t)
    assert not pilot.active and not _twists(pilot.tick(12.0))
    # The client hears of it until something steers the robot again.
    assert pilot.search == "timed_out"
    _command(pilot, face(2, 12.5, x=320.0), 12.5)
    assert pilot.search is None


def test_a_face_found_again_ends_the_search() -> None:
    pilot = onboard()
    _command(pilot, face(1, 0.0, x=40.0, range_m=2.0), 0.0)
    assert pilot.search is None
    search = pilot.pose(ODOM, 0.5)
    assert ev.of_kind(search, ev.SearchStarted) and pilot.search == "left"
    found = pilot.goal(face(2, 1.5, x=300.0, range_m=2.0), 1.5)
    assert ev.of_kind(found, ev.SearchEnded) == [ev.SearchEnded(why="found", after_s=1.0, t=1.5)]
    assert _twists(found)[-1].seq == 2  # the face steers again
    assert pilot.search is None


def test_stopping_piloting_during_a_search_ends_it() -> None:
    pilot = onboard()
    _command(pilot, face(1, 0.0, x=40.0), 0.0)
    pilot.pose(ODOM, 0.5)
    assert pilot.search == "left"
    stopped = pilot.stop(0.7)
    assert ev.of_kind(stopped, ev.SearchEnded)[0].why == "stopped" and _stops(stopped)
    assert pilot.search is None


def test_a_robot_that_turned_past_a_face_lost_on_the_right_still_searches_right() -> None:
    # The face left by the right edge; the robot, turning after it, overshot what the last goal
    # said: the face is still to the right of where it was last seen.
    pilot = onboard()
    _command(pilot, face(1, 0.0, x=600.0), 0.0)
    answers: list[Any] = []
    for k in range(1, 20):
        answers += pilot.pose(Pose(1.0, 3.0, -0.6), 0.03 * k)
    started = ev.of_kind(answers, ev.SearchStarted)
    assert [s.side for s in started] == ["right"] and pilot.search == "right"
    assert _twists(answers)[-1].angular < 0
