"""The manual override at the vehicle: the mode, drive commands and the dead-man, with the time
given by the test (vehicle_agent/core/manual.py; the agent's handling of the relay's ``mode``
and ``drive``: tests/vehicle_agent/test_channel_input.py)."""

from __future__ import annotations

import pytest

from app.protocol.control import DEADMAN_S
from tests.vehicle_agent.core.manual_sequences import SEQUENCES, run
from vehicle_agent.core.control import PROFILES, ZERO_TWIST, Twist
from vehicle_agent.core.manual import ManualDrive

DEFAULT = PROFILES["default"]
FULL = [DEFAULT.manual_linear, 0.0]
# The dead-man's contract (docs/contracts.md), written as the number it is: a test that read it
# from app.protocol.control would move with the constant it is there to hold.
DEADMAN_CONTRACT_S = 0.3


def twists(name: str) -> list[list[float] | None]:
    return [answer[0] for answer in run(SEQUENCES[name], DEFAULT)]


def test_drive_commands_move_the_turtle_only_in_manual_mode() -> None:
    assert twists("drive in auto is ignored") == [None, None]
    turn = [0.0, DEFAULT.manual_angular]
    # Taking over stops first; each command is its Twist; a zero command stops at once and the
    # dead-man has nothing left to stop.
    assert twists("take over, drive, release") == [[0.0, 0.0], turn, turn, None, [0.0, 0.0], None]


def test_the_dead_man_stops_the_turtle_once_after_the_last_command() -> None:
    answers = run(SEQUENCES["dead-man after the last command"], DEFAULT)
    assert [a[0] for a in answers] == [
        [0.0, 0.0],
        [0.5 * DEFAULT.manual_linear, -0.5 * DEFAULT.manual_angular],
        None,
        [0.0, 0.0],
        None,
    ]
    assert answers[1][3] == pytest.approx(DEADMAN_CONTRACT_S)
    assert answers[2][3] == pytest.approx(0.01)
    assert answers[3][3] is None


def test_the_dead_man_fires_0_3_s_after_the_last_command_and_not_before() -> None:
    # Built as the agent's pilot builds it, with the protocol's dead-man time.
    drive = ManualDrive(DEFAULT, DEADMAN_S)
    drive.set_mode("manual", "ann")
    assert drive.drive(1, 1.0, 0.0, 1.0) == Twist(DEFAULT.manual_linear, 0.0)
    assert drive.until_deadman(1.0) == pytest.approx(DEADMAN_CONTRACT_S)
    for t in (1.1, 1.25, 1.29):  # still moving: a held key resends within this
        assert drive.tick(t) is None, t
    assert drive.tick(1.0 + DEADMAN_CONTRACT_S) == ZERO_TWIST
    # One zero Twist only.
    assert drive.tick(1.31) is None and drive.until_deadman(1.31) is None


def test_old_commands_are_dropped_and_shares_clamped_to_the_profile_speeds() -> None:
    assert twists("old and repeated seq dropped, out-of-range clamped") == [
        [0.0, 0.0],
        [DEFAULT.manual_linear, -DEFAULT.manual_angular],
        None,
        None,
    ]


def test_a_mode_change_stops_and_a_new_operator_starts_afresh() -> None:
    answers = run(SEQUENCES["hand back stops, a new operator starts at seq 1"], DEFAULT)
    assert [a[0] for a in answers] == [
        [0.0, 0.0],
        FULL,
        [0.0, 0.0],  # handed back: stop
        None,  # auto again: the old operator's command is ignored
        None,  # the same mode again changes nothing
        [0.0, 0.0],
        [-DEFAULT.manual_linear, 0.0],  # seq 1 of the new operator is taken
    ]
    assert [(a[1], a[2]) for a in answers][-2:] == [(True, "bob"), (True, "bob")]
    assert (answers[2][1], answers[2][2]) == (False, None)


def test_a_new_link_is_back_in_auto() -> None:
    drive = ManualDrive(DEFAULT, 0.3)
    drive.set_mode("manual", "ann")
    drive.reset_link()
    assert not drive.manual and drive.operator is None
    assert drive.drive(1, 1.0, 0.0, 0.0) is None
