"""The bench's statistics on synthetic numbers whose answers are known by construction."""

from __future__ import annotations

import math

import pytest

from app.tools.bench.stats import (
    HeadingSample,
    PoseSample,
    TruthSample,
    glass_to_command_ms,
    growth_pct,
    heading_error_deg_median,
    heading_track,
    rate_per_s,
    summarize,
    wrap_angle,
)


def test_summary_of_one_to_hundred() -> None:
    s = summarize([float(v) for v in range(1, 101)])
    assert s is not None
    assert s.n == 100
    assert s.mean == pytest.approx(50.5)
    assert s.p50 == pytest.approx(50.5)
    # Linear interpolation: rank 0.95 * 99 = 94.05 -> between 95 and 96.
    assert s.p95 == pytest.approx(95.05)
    assert (s.minimum, s.maximum) == (1.0, 100.0)
    # Sample sd of 1..n is sqrt(n(n+1)/12).
    assert s.sd == pytest.approx(math.sqrt(100 * 101 / 12))


def test_summary_of_nothing_is_none_and_nan_is_refused() -> None:
    assert summarize([]) is None
    with pytest.raises(ValueError):
        summarize([1.0, float("nan")])


def test_single_sample_has_zero_spread() -> None:
    s = summarize([7.0])
    assert s is not None and s.sd == 0.0 and s.p50 == s.p95 == 7.0


def test_rate_counts_only_the_window() -> None:
    stamps = [i * 0.05 for i in range(200)]  # 20 per second for 10 s
    assert rate_per_s(stamps, 2.0, 7.0) == pytest.approx(20.0)
    with pytest.raises(ValueError):
        rate_per_s(stamps, 3.0, 3.0)


def test_glass_to_command_takes_the_first_command_per_frame() -> None:
    sent = {10: 1.000, 11: 1.033, 12: 1.066}
    commands = [
        (1.090, 10),  # 90 ms
        (1.140, 10),  # a later Twist from the same goal does not count
        (1.150, 11),  # 117 ms
        (1.500, 99),  # a frame never sent (or sent before the log began) is ignored
    ]
    assert glass_to_command_ms(sent, commands) == pytest.approx([90.0, 117.0])


def test_glass_to_command_ignores_commands_out_of_order_in_the_log() -> None:
    sent = {5: 2.0}
    assert glass_to_command_ms(sent, [(2.2, 5), (2.1, 5)]) == pytest.approx([100.0])


@pytest.mark.parametrize(
    ("angle", "expected"),
    [(0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2)],
)
def test_wrap_angle(angle: float, expected: float) -> None:
    assert wrap_angle(angle) == pytest.approx(expected)


def identity_terrain(x: float, y: float, w: int, h: int) -> tuple[float, float]:
    return x, y


def test_heading_track_measures_against_the_target_shown_at_the_time() -> None:
    truth = [TruthSample(0.0, 10.0, 0.0, 20, 20), TruthSample(1.0, 0.0, 10.0, 20, 20)]
    poses = [
        PoseSample(-0.5, 0.0, 0.0, 0.0),  # before any frame: skipped
        PoseSample(0.5, 0.0, 0.0, math.radians(10)),  # target due east: 10 deg off
        PoseSample(1.5, 0.0, 0.0, math.radians(80)),  # target due north: 10 deg short
    ]
    track = heading_track(poses, truth, identity_terrain)
    assert [s.t for s in track] == [0.5, 1.5]
    assert math.degrees(track[0].error) == pytest.approx(10.0)
    assert math.degrees(track[1].error) == pytest.approx(-10.0)
    assert math.degrees(track[1].truth) == pytest.approx(90.0)


def test_heading_error_wraps_across_pi() -> None:
    truth = [TruthSample(0.0, -10.0, 0.1, 20, 20)]  # almost due west, just above
    pose = PoseSample(0.0, 0.0, 0.0, -math.pi + 0.01)  # just below due west
    (sample,) = heading_track([pose], truth, identity_terrain)
    assert abs(sample.error) < 0.03


def test_heading_track_skips_a_target_on_top_of_the_turtle() -> None:
    truth = [TruthSample(0.0, 1.0, 1.0, 20, 20)]
    assert heading_track([PoseSample(0.0, 1.0, 1.01, 0.0)], truth, identity_terrain) == []


def test_median_heading_error_after_settle() -> None:
    track = [HeadingSample(t, 0.0, 0.0, math.radians(e)) for t, e in [(0, 90), (1, -2), (2, 4)]]
    assert heading_error_deg_median(track, after=1.0) == pytest.approx(3.0)
    assert heading_error_deg_median(track, after=5.0) is None


def test_growth_pct() -> None:
    assert growth_pct(100.0, 103.0) == pytest.approx(3.0)
    assert growth_pct(200.0, 100.0) == pytest.approx(-50.0)
    with pytest.raises(ValueError):
        growth_pct(0.0, 1.0)
