"""The data-channel models: what each side accepts, and why it refuses the rest."""

from __future__ import annotations

import math

import pytest

from app.protocol import channels
from app.protocol.channels import AUTOPILOT_CHANNEL
from tests.protocol.samples import GOAL, SAMPLES, Sample


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda s: f"{s.label}-{s.role}-{s.text[:40]}")
def test_each_sample_gets_its_verdict_naming_the_field(sample: Sample) -> None:
    parsed = channels.parse(sample.text, sample.label, sample.role)
    assert isinstance(parsed, channels.Refused) != sample.valid, parsed
    if isinstance(parsed, channels.Refused) and sample.field is not None:
        assert f"'{sample.field}" in parsed.reason, parsed.reason


def test_nan_and_infinity_are_refused_even_when_json_lets_them_through() -> None:
    # Python's json module reads NaN and Infinity; the models must not.
    for bad in (math.nan, math.inf, -math.inf):
        refused = channels.validate({**GOAL, "x": bad}, AUTOPILOT_CHANNEL, "vehicle")
        assert isinstance(refused, channels.Refused) and "'x'" in refused.reason


def test_a_built_message_round_trips_through_the_wire() -> None:
    goal = channels.Goal(seq=1, op="face", x=10.0, y=20.0, w=640, h=480, t=5.0, frame=7)
    assert channels.parse(channels.dump(goal), AUTOPILOT_CHANNEL, "vehicle") == goal


def test_a_goal_is_locked_only_when_its_relay_says_so() -> None:
    # An older relay sends no ``locked``: its goals are accepted, unlocked.
    for extra, locked in (({}, False), ({"locked": False}, False), ({"locked": True}, True)):
        parsed = channels.validate({**GOAL, **extra}, AUTOPILOT_CHANNEL, "vehicle")
        assert isinstance(parsed, channels.Goal) and parsed.locked is locked, (extra, parsed)


def test_the_same_type_is_refused_on_a_channel_that_does_not_carry_it() -> None:
    refused = channels.parse('{"type": "setOp", "op": "face"}', AUTOPILOT_CHANNEL, "vehicle")
    assert isinstance(refused, channels.Refused)
    assert refused.ref == "setOp" and "unknown message type" in refused.reason


def test_every_model_is_received_by_someone() -> None:
    received = {
        channels.type_of(model)
        for by_role in channels.RECEIVERS.values()
        for models in by_role.values()
        for model in models
    }
    assert received == {channels.type_of(m) for m in channels.ChannelMessage.__args__}
