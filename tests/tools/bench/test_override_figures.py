"""``deadman_stop_s`` from the agent's events: the last moving drive command → the zero Twist
that followed, never the zero Twist of a stop command (a release that came late)."""

from __future__ import annotations

import pytest

from app.protocol.events import DriveReceived, TwistSent
from app.tools.bench.override import PERIOD_S, _deadman_stop_s


def drive(t: float, moving: bool) -> DriveReceived:
    return DriveReceived(seq=1, applied=True, moving=moving, t=t)


def twist(t: float, angular: float) -> TwistSent:
    return TwistSent(seq=None, frame=None, linear=0.0, angular=angular, t=t)


def test_the_zero_twist_after_the_last_moving_command() -> None:
    start = 10.0 + PERIOD_S
    events = [
        drive(start + 0.1, False),  # the last press's release, late: its own stop
        twist(start + 0.1, 0.0),
        drive(start + 0.5, True),
        twist(start + 0.5, 2.0),
        drive(start + 0.6, True),
        twist(start + 0.6, 2.0),
        twist(start + 0.9, 0.0),  # the dead-man
    ]
    assert _deadman_stop_s(events, 10.0) == pytest.approx(0.3)
    assert _deadman_stop_s(events[:4], 10.0) is None
