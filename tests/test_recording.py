"""The recording formats (app/recording.py): schemas that follow the event dataclasses, event
logs read back typed, and a reader that does not need the recorder's media stack."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import pytest

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
