"""Latest-wins on the lossy goal channel: newer seq only, stale goals dropped, clock-independent."""

from __future__ import annotations

import pytest

from vehicle_agent.freshness import FreshnessRule, GoalGate

RULE = FreshnessRule(max_age_s=0.5, window_s=5.0)
CLOCK_SKEW_S = 1234.5  # the sender's clock is this far behind the vehicle's


def _sent_ms(at_s: float) -> float:
    return (at_s - CLOCK_SKEW_S) * 1000


def test_in_order_goals_pass_and_an_older_or_repeated_seq_does_not() -> None:
    gate = GoalGate(RULE)
    assert [gate.admit(seq, _sent_ms(seq * 0.05), seq * 0.05 + 0.02) for seq in range(5)] == [
        "fresh"
    ] * 5
    assert gate.admit(3, _sent_ms(0.15), 0.3) == "old"  # overtaken on the unordered channel
    assert gate.admit(4, _sent_ms(0.2), 0.31) == "old"  # a duplicate
    assert gate.admit(6, _sent_ms(0.3), 0.32) == "fresh"  # a gap (5 was lost) is fine
    assert gate.last_seq == 6


def test_a_goal_held_back_longer_than_the_bound_is_stale_whatever_the_clocks() -> None:
    gate = GoalGate(RULE)
    assert gate.admit(1, _sent_ms(10.0), 10.03) == "fresh"
    # Sent at 10.05 but delivered 0.6 s later than the quickest goal's transit: stale.
    assert gate.admit(2, _sent_ms(10.05), 10.05 + 0.03 + 0.6) == "stale"
    # A stale goal is not applied, so it does not raise the bar for the next one.
    assert gate.last_seq == 1
    assert gate.admit(3, _sent_ms(10.7), 10.73) == "fresh"


def test_the_burst_after_an_outage_is_dropped_and_the_first_live_goal_applies() -> None:
    gate = GoalGate(RULE)
    for seq in range(10):
        assert gate.admit(seq, _sent_ms(seq * 0.05), seq * 0.05 + 0.02) == "fresh"
    # Goals 10..69 were queued at the sender during a 3 s outage and arrive together at 3.6 s.
    # Those that waited more than the bound beyond the usual 0.02 s transit are stale; the
    # newest few of the burst are recent enough to apply, each newer than the last.
    for seq in range(10, 70):
        waited = 3.6 - seq * 0.05 - 0.02
        assert gate.admit(seq, _sent_ms(seq * 0.05), 3.6) == (
            "stale" if waited > RULE.max_age_s else "fresh"
        ), seq
    assert gate.admit(72, _sent_ms(3.6), 3.62) == "fresh"


def test_a_path_that_got_slower_for_good_is_accepted_once_the_window_forgets_the_fast_one() -> None:
    gate = GoalGate(RULE)
    assert gate.admit(0, _sent_ms(0.0), 0.01) == "fresh"
    verdicts = {seq: gate.admit(seq, _sent_ms(seq * 0.1), seq * 0.1 + 0.8) for seq in range(1, 80)}
    assert verdicts[1] == "stale"
    assert verdicts[79] == "fresh"
    first_fresh = min(seq for seq, verdict in verdicts.items() if verdict == "fresh")
    assert first_fresh * 0.1 + 0.8 == pytest.approx(RULE.window_s, abs=0.15)


def test_reset_starts_a_new_link_from_any_seq() -> None:
    gate = GoalGate(RULE)
    assert gate.admit(500, _sent_ms(1.0), 1.01) == "fresh"
    gate.reset()
    assert gate.admit(0, _sent_ms(50.0), 50.01) == "fresh"
