"""The recording formats (app/recording.py): schemas that follow the event dataclasses, event
logs read back typed, and a reader that does not need the recorder's media stack."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.writer import Writer

from app import recording
from app.protocol import events as ev
from app.protocol.events import EventError
from tests.protocol.test_events import SAMPLES

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("kind", list(recording.EVENT_CHANNELS), ids=lambda k: k.kind)
def test_each_recorded_kind_s_schema_has_exactly_its_dataclass_fields(
    kind: type[ev.Event],
) -> None:
    topic, schema = next(
        (t, s) for t, s in recording.channels() if t == recording.EVENT_CHANNELS[kind].topic
    )
    assert schema["title"] == recording.EVENT_CHANNELS[kind].schema
    assert set(schema["properties"]) == {f.name for f in dataclasses.fields(kind)}
    # And a recorded message of the kind has exactly those fields.
    sample = next(s for s in SAMPLES if isinstance(s, kind))
    assert set(recording.message(sample)) == set(schema["properties"]), topic


def _twists_file(path: Path, messages: list[dict[str, object]]) -> Path:
    """An MCAP file of ``messages`` on the Twists' channel."""
    topic = recording.EVENT_CHANNELS[ev.TwistSent].topic
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema(name="any", encoding="jsonschema", data=b"{}")
        channel = writer.register_channel(topic, message_encoding="json", schema_id=schema)
        for n, fields in enumerate(messages):
            writer.add_message(
                channel, log_time=n, data=json.dumps(fields).encode(), publish_time=n
            )
        writer.finish()  # type: ignore[no-untyped-call]
    return path


def test_a_twist_is_recorded_as_a_geometry_msgs_twist_and_read_back(tmp_path: Path) -> None:
    sent = ev.TwistSent(seq=3, frame=103, linear=0.4, angular=-0.7, t=1.5)
    fields = recording.message(sent)
    # Where a plot finds them: `.linear.x` and `.angular.z`, as on a ROS robot's cmd_vel.
    assert fields["linear"] == {"x": 0.4, "y": 0.0, "z": 0.0}
    assert fields["angular"] == {"x": 0.0, "y": 0.0, "z": -0.7}
    schema = dict(recording.channels())[recording.EVENT_CHANNELS[ev.TwistSent].topic]
    for name in ("linear", "angular"):
        assert schema["properties"][name]["type"] == "object"
        assert set(schema["properties"][name]["properties"]) == {"x", "y", "z"}
    # A recording from before the vectors (flat speeds) reads back alike.
    flat = {**fields, "linear": 0.4, "angular": -0.7}
    path = _twists_file(tmp_path / "twists.mcap", [fields, flat])
    assert [event for _, event in recording.events([path])] == [sent, sent]
    # A vector without its axis is not a Twist.
    broken = _twists_file(tmp_path / "broken.mcap", [{**fields, "angular": {"x": 0.0}}])
    with pytest.raises(recording.RecordingError, match="not a 'twist' event"):
        list(recording.events([broken]))


def test_a_field_s_type_becomes_its_json_schema() -> None:
    @dataclasses.dataclass(frozen=True, kw_only=True)
    class Probe(ev.Event):
        kind = "probe"
        count: int
        share: float
        name: str | None
        on: bool
        why: ev.DropReason | None
        names: tuple[str, ...]

    properties = recording.json_schema(Probe, "autopilot.Probe")["properties"]
    assert properties["count"] == {"type": "integer"}
    assert properties["share"] == {"type": "number"}
    assert properties["name"] == {"type": ["string", "null"]}
    assert properties["on"] == {"type": "boolean"}
    assert properties["why"] == {
        "type": ["string", "null"],
        "enum": ["old", "stale", "future", "manual", None],
    }
    assert properties["names"] == {"type": "array", "items": {"type": "string"}}
    assert properties["t"]["type"] == "number"


def test_an_event_log_reads_back_typed_and_a_growing_one_leaves_its_last_half_line(
    tmp_path: Path,
) -> None:
    path = tmp_path / "events.jsonl"
    lines = [recording.event_line(event) for event in SAMPLES]
    path.write_text("\n".join(lines) + "\n")
    assert recording.read_event_log(path) == SAMPLES
    # The agent is still writing: half a line at the end is not yet an event.
    with path.open("a") as log:
        log.write(lines[1][:20])
    assert recording.read_event_log(path, growing=True) == SAMPLES
    with pytest.raises(EventError):
        recording.read_event_log(path)


def test_replay_reads_recordings_without_the_recorder_s_media_stack() -> None:
    # The recorder drags in aiortc, PyAV and the agent; the reader must not.
    code = (
        "import sys, json, app.tools.replay; "
        "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('aiortc', 'av', 'vehicle_agent'))))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True
    )
    assert json.loads(done.stdout) == []
