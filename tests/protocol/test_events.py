"""The event records: one per kind, written as the log's lines and read back as they were."""

from __future__ import annotations

import json

import pytest

from app.protocol import events as ev

# One of every kind, each field set away from its default.
SAMPLES: list[ev.AnyEvent] = [
    ev.FrameSent(frame=7, face_x=160.5, face_y=240.0, jump=True, t=1.0),
    ev.GoalApplied(seq=3, op="face", frame=7, x=100.0, y=200.5, w=640, h=480, t=1.1),
    ev.GoalDropped(seq=2, frame=None, why="manual", t=1.2),
    ev.ModeChanged(mode="manual", operator="ann", t=1.3),
    ev.DriveReceived(seq=4, applied=True, moving=False, t=1.4),
    ev.TwistSent(seq=None, frame=None, linear=0.0, angular=-0.5, t=1.5),
    ev.SearchStarted(side="right", t=1.55),
    ev.SearchEnded(why="timed_out", after_s=5.9, t=1.56),
    ev.PoseReport(x=5.5, y=5.25, theta=1.57, sent=False, t=1.6),
    ev.LinkChanged(
        state="up",
        relay="relay-1",
        reason="because",
        local_candidates=("host", "relay"),
        selected="relay",
        t=1.7,
    ),
    ev.SpawnStep(ok=True, x=5.5, y=5.5, theta=1.5708, reason="r", t=1.8),
    ev.RecorderTotals(
        images=10,
        messages=200,
        dropped=1,
        files=2,
        frames=300,
        frames_held=120,
        cpu_s=0.5,
        loop_cpu_s=0.2,
        writer_cpu_s=0.3,
        seconds=60.0,
        t=1.9,
    ),
]


def test_every_kind_has_a_sample_and_a_unique_name() -> None:
    assert {type(sample) for sample in SAMPLES} == set(ev.KINDS.values())
    assert len(ev.KINDS) == len(SAMPLES)


@pytest.mark.parametrize("event", SAMPLES, ids=lambda e: e.kind)
def test_a_log_line_names_its_kind_first_and_its_time_last_and_reads_back(
    event: ev.AnyEvent,
) -> None:
    line = json.dumps(ev.record(event))
    keys = list(json.loads(line))
    assert keys[0] == "ev" and keys[-1] == "t"
    assert json.loads(line)["ev"] == event.kind
    assert ev.from_json(line) == event


def test_the_lines_the_bench_reads_keep_their_field_names() -> None:
    # What app/tools/bench and earlier logs rely on: the names, not just a round trip.
    assert ev.record(SAMPLES[1]) == {
        "ev": "goal",
        "seq": 3,
        "op": "face",
        "frame": 7,
        "x": 100.0,
        "y": 200.5,
        "w": 640,
        "h": 480,
        "box_w": None,
        "box_h": None,
        "locked": False,
        "t": 1.1,
    }
    # A log from before ``locked`` reads back: its goals were not locked.
    earlier = {k: v for k, v in ev.record(SAMPLES[1]).items() if k != "locked"}
    assert ev.from_json(json.dumps(earlier)) == SAMPLES[1]
    twist = ev.record(SAMPLES[5])
    assert twist == {
        "ev": "twist",
        "seq": None,
        "frame": None,
        "linear": 0.0,
        "angular": -0.5,
        "t": 1.5,
    }


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("not json", "not JSON"),
        ("[1, 2]", "unknown event kind"),
        ('{"ev": "dance", "t": 1}', "unknown event kind 'dance'"),
        ('{"ev": "goal_dropped", "seq": 1, "frame": null, "why": "bored", "t": 1}', "why"),
        (
            '{"ev": "twist", "seq": null, "frame": null, "linear": "1", "angular": 0, "t": 1}',
            "linear",
        ),
        ('{"ev": "pose", "x": 1, "y": 2, "theta": 3, "t": 4}', "sent"),
    ],
)
def test_what_is_not_an_event_is_refused_naming_why(line: str, says: str) -> None:
    with pytest.raises(ev.EventError, match=says):
        ev.from_json(line)


def test_a_later_field_is_ignored_on_reading() -> None:
    line = '{"ev": "mode", "mode": "auto", "operator": null, "colour": "red", "t": 2}'
    assert ev.from_json(line) == ev.ModeChanged(mode="auto", operator=None, t=2.0)


def test_of_kind_keeps_order_and_type() -> None:
    assert ev.of_kind(SAMPLES * 2, ev.TwistSent) == [SAMPLES[5], SAMPLES[5]]
