"""The argparse types and options every command shares (app/arguments.py)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from functools import partial

import pytest

from app.arguments import (
    add_relay_profile,
    add_vehicle_profile,
    non_negative_integer,
    non_negative_number,
    port,
    positive_integer,
    positive_number,
)
from app.protocol import control, relay_profiles


@pytest.mark.parametrize(
    ("parse", "text", "value"),
    [
        (positive_number, "0.5", 0.5),
        (positive_number, "1e3", 1000.0),
        (non_negative_number, "0", 0.0),
        (non_negative_number, "2.5", 2.5),
        (positive_integer, "3", 3),
        (non_negative_integer, "0", 0),
        (port, "1", 1),
        (port, "65535", 65535),
    ],
)
def test_accepts(parse: Callable[[str], float], text: str, value: float) -> None:
    assert parse(text) == value


# What each type refuses, and a word of the reason it gives.
REFUSED: dict[Callable[[str], float], dict[str, str]] = {
    positive_number: {
        "fast": "expected a number",
        "nan": "finite",
        "-inf": "finite",
        "0": "positive",
    },
    non_negative_number: {"NaN": "finite", "inf": "finite", "-0.1": ">= 0"},
    positive_integer: {"1.5": "whole number", "0": ">= 1"},
    non_negative_integer: {"two": "whole number", "-1": ">= 0"},
    port: {"0": ">= 1", "65536": "65535", "http": "whole number"},
}


@pytest.mark.parametrize(
    ("parse", "text", "words"),
    [(parse, text, words) for parse, cases in REFUSED.items() for text, words in cases.items()],
)
def test_refuses_with_the_reason(parse: Callable[[str], float], text: str, words: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=words) as refused:
        parse(text)
    assert repr(text) in str(refused.value)


@pytest.mark.parametrize(
    ("add", "profiles", "foreign"),
    [
        (add_vehicle_profile, list(control.PROFILES), "fastest"),
        # follow is a vehicle profile: the relay paces it as default and has no such profile.
        (
            partial(add_relay_profile, purpose="relay profile"),
            list(relay_profiles.PROFILES),
            "follow",
        ),
    ],
)
def test_profile_options_offer_the_protocol_profiles(
    add: Callable[[argparse.ArgumentParser], None], profiles: list[str], foreign: str
) -> None:
    parser = argparse.ArgumentParser(exit_on_error=False)
    add(parser)
    assert parser.parse_args([]).profile == relay_profiles.DEFAULT_PROFILE
    for name in profiles:
        assert parser.parse_args(["--profile", name]).profile == name
    with pytest.raises(argparse.ArgumentError, match=foreign):
        parser.parse_args(["--profile", foreign])
