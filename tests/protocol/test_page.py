"""The page config (app/protocol/page.py): one conversion, each fact once."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from app.protocol.control import control_config
from app.protocol.opencv import RELAY_OPENCV_BUILD
from app.protocol.page import BaseConfig, Verbatim, page_protocol, to_json
from app.protocol.ros import ROS_CONFIG


@dataclass(frozen=True)
class Inner:
    max_age_s: float
    never_s: float


@dataclass(frozen=True)
class Outer:
    snake_case_name: tuple[int, ...]
    by_label: dict[str, Inner]
    kept: Verbatim


def test_field_names_become_camel_case_and_data_keys_stay_as_they_are() -> None:
    value = Outer(
        snake_case_name=(1, 2),
        by_label={"autopilot-state": Inner(0.5, math.inf), "snake_key": Inner(1.0, 2.0)},
        kept=Verbatim({"max_items": [1], "nested_key": {"a_b": math.inf}}),
    )
    assert to_json(value) == {
        "snakeCaseName": [1, 2],
        "byLabel": {
            "autopilot-state": {"maxAgeS": 0.5, "neverS": None},
            "snake_key": {"maxAgeS": 1.0, "neverS": 2.0},
        },
        "kept": {"max_items": [1], "nested_key": {"a_b": math.inf}},
    }


def values(json: Any) -> list[Any]:
    """Every leaf value of ``json``."""
    if isinstance(json, dict):
        return [leaf for item in json.values() for leaf in values(item)]
    if isinstance(json, list):
        return [leaf for item in json for leaf in values(item)]
    return [json]


def test_the_world_size_reaches_a_role_page_once() -> None:
    # What a role page embeds beside its per-request fields: the control law's numbers, the ROS
    # type table and the protocol.
    config = to_json(BaseConfig(page_protocol())) | {
        "control": to_json(control_config()),
        "rosTypes": to_json(ROS_CONFIG),
    }
    leaves = values(config)
    assert leaves.count(11.088889) == 1 and leaves.count(5.544445) == 1
    assert config["control"]["worldSize"] == 11.088889
    assert config["control"]["terrainCentre"] == 5.544445


def test_the_protocol_carries_the_frame_tag_lock_and_health_numbers() -> None:
    protocol = to_json(page_protocol())
    assert protocol["frameTag"] == {"blocksPerWidth": 40, "markerBlocks": 2, "bits": 24}
    assert protocol["lock"] == {
        "searchAfterS": 1.0,
        "releaseAfterS": 3.0,
        "maxScale": 1.4,
        "reach": 1.0,
        "near": 0.5,
        "clickSearch": 0.6,
        "lookBins": [16, 16],
        "minLikeness": 0.9,
    }
    assert protocol["health"] == {"periodS": 1.0, "maxLossPct": 5.0, "maxRttMs": 300.0}
    assert protocol["channels"] == {
        "autopilot": "autopilot",
        "autopilotState": "autopilot-state",
        "control": "control",
    }
    assert set(protocol["schemas"]) == {"autopilot", "autopilot-state", "control"}
    # Every page's analyzer loads the relay's OpenCV.js unless its ?opencv= says otherwise.
    assert protocol["opencvBuild"] == RELAY_OPENCV_BUILD
