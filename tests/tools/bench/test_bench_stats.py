"""The bench's statistics on synthetic numbers whose answers are known by construction."""

from __future__ import annotations

import math

import pytest

from app.protocol.angles import wrap_angle
from app.tools.bench.stats import (
    FaceSample,
    HeadingSample,
    PoseSample,
    TruthSample,
    glass_to_command_ms,
    growth_pct,
    heading_error_deg_median,
    heading_track,
    rate_per_s,
    recall_after_jump_pct,
    standoff_errors,
    summarize,
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


def leaping_face(frames: int, leap_at: tuple[int, ...]) -> list[FaceSample]:
    """A face at x = 100 px that leaps to 500 px (and back) at the given frames; 640x480."""
    track, x = [], 100.0
    for f in range(frames):
        if f in leap_at:
            x = 600.0 - x
        track.append(FaceSample(f, x, 200.0))
    return track


def test_recall_counts_jumps_answered_within_three_frames_at_the_new_place() -> None:
    track = leaping_face(40, (10, 20, 30))
    goals = {f: (s.x + 3, s.y - 2) for s in track for f in [s.frame]}
    # Every frame answered: every jump is caught.
    assert recall_after_jump_pct(track, goals, 640, 480) == (100.0, 3)
    # After the jump at 20 the goals of frames 20..23 are missing, the one of 24 is too late.
    late = {f: p for f, p in goals.items() if not 20 <= f <= 23}
    assert recall_after_jump_pct(track, late, 640, 480) == (pytest.approx(200 / 3), 3)
    # A goal from frame 32 still pointing at the old place does not count for the jump at 30.
    stale = {f: p for f, p in goals.items() if not 30 <= f <= 33} | {32: (100.0, 200.0)}
    assert recall_after_jump_pct(track, stale, 640, 480)[0] == pytest.approx(200 / 3)


def test_recall_counts_appearances_and_the_scene_jump_flag_but_not_glides() -> None:
    # Out of view (x < 0) for 5 frames, then in view and gliding 10 px per frame.
    track = [FaceSample(f, -50.0 if f < 5 else 10.0 * f, 200.0) for f in range(30)]
    assert recall_after_jump_pct(track, {}, 640, 480) == (0.0, 1)
    flagged = [FaceSample(s.frame, s.x, s.y, jump=s.frame == 15) for s in track]
    goals = {f: (10.0 * f, 200.0) for f in range(5, 9)}
    assert recall_after_jump_pct(flagged, goals, 640, 480) == (50.0, 2)


def test_recall_without_any_jump_is_not_measured() -> None:
    track = [FaceSample(f, 100.0 + f, 200.0) for f in range(30)]
    assert recall_after_jump_pct(track, {}, 640, 480) == (None, 0)
    # A jump too close to the end of the track to see 3 frames after it is not counted.
    assert recall_after_jump_pct(leaping_face(12, (10,)), {}, 640, 480) == (None, 0)


def test_standoff_error_is_the_distance_off_the_standoff_from_the_target_shown() -> None:
    def identity(x: float, y: float, w: int, h: int) -> tuple[float, float]:
        return x, y

    # The target sits at (0, 0) until t = 1, then leaps to (10, 0).
    truth = [TruthSample(0.0, 0.0, 0.0, 1, 1), TruthSample(1.0, 10.0, 0.0, 1, 1)]
    poses = [
        PoseSample(-0.5, 1.0, 0.0, 0.0),  # before the first frame: skipped
        PoseSample(0.5, 1.0, 0.0, 0.0),  # exactly at the 1 m standoff
        PoseSample(0.9, 0.0, 3.0, 0.0),  # 3 m off the target: 2 m too far
        PoseSample(1.5, 9.5, 0.0, 0.0),  # 0.5 m from the leapt target: 0.5 m too close
    ]
    errors = standoff_errors(poses, truth, identity, 1.0)
    assert [t for t, _ in errors] == [0.5, 0.9, 1.5]
    assert [e for _, e in errors] == pytest.approx([0.0, 2.0, 0.5])
