"""Latest-wins on the lossy goal channel: newer seq only, stale goals dropped, clock-independent."""

from __future__ import annotations

import pytest

from app.protocol.channels import (
    GOAL_AGE_WINDOW_S,
    GOAL_MAX_AGE_S,
    GOAL_MAX_CLOCK_SKEW_S,
    GOAL_SEQ_BURST,
    GOAL_SEQ_RATE_HZ,
)
from tests.vehicle_agent.core.freshness_sequences import SEQUENCES
from tests.vehicle_agent.core.freshness_sequences import WALL_MS as SHARED_WALL_MS
from vehicle_agent.core.freshness import FreshnessRule, GoalGate

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


# --- goals from the future ------------------------------------------------------------------

WALL_MS = 1_800_000_000_000.0  # the receiver's wall clock, fixed for these tests


def future_gate() -> GoalGate:
    return GoalGate(RULE, wall_clock=lambda: WALL_MS)


def test_a_seq_beyond_the_reach_of_the_link_is_refused_and_changes_nothing() -> None:
    gate = future_gate()
    assert gate.admit(1, _sent_ms(0.0), 0.0) == "fresh"
    # Within 1 s of the last goal applied, a relay can have numbered at most burst + rate goals.
    reach = RULE.seq_burst + RULE.seq_rate_hz * 1.0
    assert gate.admit(1 + int(reach) + 1, _sent_ms(1.0), 1.0) == "future"
    assert gate.admit(2**62, _sent_ms(1.0), 1.0) == "future"
    assert gate.last_seq == 1
    # The next real goals apply, and one within the reach too (a gap of lost goals).
    assert gate.admit(2, _sent_ms(1.05), 1.05) == "fresh"
    assert gate.admit(1 + int(reach), _sent_ms(2.05), 2.05) == "fresh"


def test_a_goal_stamped_ahead_of_this_clock_by_more_than_the_skew_is_refused() -> None:
    gate = future_gate()
    skew_ms = RULE.max_skew_s * 1000
    assert gate.admit(1, WALL_MS - 20, 0.0) == "fresh"
    assert gate.admit(2, WALL_MS + 3_600_000, 0.05) == "future"  # an hour ahead
    assert gate.admit(3, WALL_MS + skew_ms + 1, 0.1) == "future"
    # Refused, neither moved the path's base delay: the next real goals are on time.
    assert [gate.admit(seq, WALL_MS - 20 + seq * 50, seq * 0.05) for seq in (4, 5, 6)] == [
        "fresh"
    ] * 3
    assert gate.admit(7, WALL_MS + skew_ms - 1, 0.35) == "fresh"  # within the skew: believed


def test_the_default_rule_is_the_protocol_s() -> None:
    assert FreshnessRule() == FreshnessRule(
        max_age_s=GOAL_MAX_AGE_S,
        window_s=GOAL_AGE_WINDOW_S,
        max_skew_s=GOAL_MAX_CLOCK_SKEW_S,
        seq_rate_hz=GOAL_SEQ_RATE_HZ,
        seq_burst=GOAL_SEQ_BURST,
    )


@pytest.mark.parametrize("name", SEQUENCES)
def test_the_shared_sequences_meet_the_rule(name: str) -> None:
    gate = GoalGate(FreshnessRule(), wall_clock=lambda: SHARED_WALL_MS)
    verdicts = [(seq, gate.admit(seq, sent, now)) for seq, sent, now in SEQUENCES[name]]
    future = {seq for seq, verdict in verdicts if verdict == "future"}
    if name == "from the future":
        assert future == {2**40, 2**52, 81, 101, 161 + 120}
        # Every real goal after them still applied.
        applied = [seq for seq, verdict in verdicts if verdict == "fresh"]
        assert applied == list(range(1, 201))
    else:
        assert future == set()
        assert {"fresh", "old", "stale"} <= {verdict for _, verdict in verdicts}
