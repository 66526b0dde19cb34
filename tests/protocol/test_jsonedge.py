"""The JSON edge: what Python's json accepts but a peer must not send gets one clear error."""

from __future__ import annotations

import math

import pytest

from app.protocol.jsonedge import MAX_DEPTH, JsonEdgeError, dumps, loads

HOSTILE = {
    "NaN literal": ('{"x": NaN}', "NaN"),
    "Infinity literal": ("[Infinity]", "Infinity"),
    "-Infinity literal": ('{"a": -Infinity}', "-Infinity"),
    "float overflowing to infinity": ('{"x": 1e999}', "finite"),
    "5000-digit integer": ("1" * 5000, "5000 digits"),
    "integer past 2**63": (str(2**63 + 1), "outside the range"),
    "3000-deep nesting": ("[" * 3000 + "]" * 3000, "nested deeper"),
    "nesting just past the bound": ("[" * (MAX_DEPTH + 1) + "]" * (MAX_DEPTH + 1), "nested"),
    "deep objects": ('{"a":' * (MAX_DEPTH + 1) + "1" + "}" * (MAX_DEPTH + 1), "nested"),
    "invalid UTF-8": (b'{"type": "\xff"}', "UTF-8"),
    "malformed": ("{oops", "malformed JSON"),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_hostile_input_is_one_clear_error(case: str) -> None:
    text, words = HOSTILE[case]
    with pytest.raises(JsonEdgeError, match=words):
        loads(text)


def test_ordinary_json_still_parses() -> None:
    nested = "[" * MAX_DEPTH + "]" * MAX_DEPTH
    assert loads(nested) is not None
    assert loads(str(2**63)) == 2**63
    assert loads(b'{"x": 1.5, "n": -12, "s": "\xc3\xa9"}') == {"x": 1.5, "n": -12, "s": "é"}


def test_a_json_edge_error_is_a_value_error_for_callers_that_catch_those() -> None:
    assert issubclass(JsonEdgeError, ValueError)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_outgoing_json_never_contains_nan_or_infinity(value: float) -> None:
    with pytest.raises(ValueError):
        dumps({"type": "pose", "x": value})
    assert loads(dumps({"type": "pose", "x": 1.0})) == {"type": "pose", "x": 1.0}
