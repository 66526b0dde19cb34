"""The onboard bench's figures from hand-made tracks (app/tools/bench/onboard_stats.py)."""

from __future__ import annotations

import math

import pytest

from app.tools.bench.onboard_stats import (
    Reacquisition,
    Sighting,
    bearing_errors_deg,
    reacquisitions,
    sightings,
    standoff_errors_m,
)
from app.tools.bench.stats import PoseSample

HFOV = math.radians(60)


def deg(t: float, bearing_deg: float, distance: float = 1.2) -> Sighting:
    return Sighting(t, math.radians(bearing_deg), distance)


def test_the_walker_is_seen_at_its_bearing_from_the_robots_heading_and_its_distance() -> None:
    poses = [
        PoseSample(0.0, 1.0, 3.0, 0.0),  # facing east, the walker 2 m east: dead ahead
        PoseSample(0.1, 1.0, 3.0, math.pi / 2),  # facing north: the walker is to the right
        PoseSample(0.2, 1.0, 3.0, 0.0),  # the walker unknown then: skipped
    ]
    track = sightings(poses, lambda t: None if t > 0.15 else (3.0, 3.0))
    assert [s.t for s in track] == [0.0, 0.1]
    assert track[0].bearing == pytest.approx(0.0) and track[0].distance == pytest.approx(2.0)
    assert track[1].bearing == pytest.approx(-math.pi / 2)


def test_errors_count_from_the_first_acquisition_and_only_in_view() -> None:
    track = [
        deg(0.0, 25.0, 3.0),  # before the robot first had it within 5°: not counted
        deg(0.1, 4.0, 2.0),  # acquired
        deg(0.2, -8.0, 1.5),
        deg(0.3, 45.0, 1.0),  # out of the 60° view: not counted
        deg(0.4, 2.0, 1.1),
    ]
    assert bearing_errors_deg(track, HFOV) == pytest.approx([4.0, 8.0, 2.0])
    assert standoff_errors_m(track, HFOV, 1.2) == pytest.approx([0.8, 0.3, -0.1])


def test_never_acquired_gives_no_figures() -> None:
    track = [deg(0.0, 20.0), deg(0.1, -40.0)]
    assert bearing_errors_deg(track, HFOV) == []
    assert reacquisitions(track, HFOV) == []


def test_a_reacquisition_runs_from_leaving_the_view_to_back_within_five_degrees() -> None:
    track = [
        deg(0.0, 0.0),
        deg(0.5, 20.0),
        deg(1.0, 31.0),  # left the 60° view by the left
        deg(2.0, 120.0),  # behind
        deg(3.0, 20.0),  # in view again, not yet on it
        deg(3.5, 4.9),  # back: 2.5 s after it left
        deg(4.0, -35.0),  # left by the right
        deg(5.0, -50.0),  # and not back before the end
    ]
    assert reacquisitions(track, HFOV) == [
        Reacquisition(1.0, "left", pytest.approx(2.5)),
        Reacquisition(4.0, "right", None),
    ]
