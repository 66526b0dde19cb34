"""The browser vehicle's pilot (app/static/js/core/pilot.js) answers as the agent's does
(vehicle_agent/core/pilot.py): the shared sequences of tests/vehicle_agent/core/pilot_sequences.py
give the same event records (the agent's event-log lines, field for field), the same wake-ups and
modes. pilot.js is built as the vehicle page builds it, from the numbers its config carries; the
rules themselves are stated in tests/vehicle_agent/core/test_pilot.py, and one of them again
here."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.protocol.control import PROFILES, control_config
from app.protocol.page import page_protocol, robot_config, to_json
from app.protocol.robot import PRESETS
from app.server.serve import RunningServer
from e2e.helpers import module_page
from tests.vehicle_agent.core.pilot_sequences import ROBOTS, SEQUENCES, goal, run

pytestmark = [pytest.mark.browser]

# The pilot as pages/vehicle.js builds it, fed one sequence: each step's records, next tick,
# mode, operator and search status.
RUN_JS = """([steps, constants, freshness, robot, profile]) => {
  const law = new control.ControlLaw(constants);
  const driven = new pilot.Pilot(law, law.profiles[profile], robot, {
    deadmanS: constants.deadmanS,
    tickS: constants.tickS,
    freshness,
  });
  const feed = (kind, t, args) => {
    switch (kind) {
      case 'frame': driven.frame(args[0], t); return [];
      case 'goal': return driven.goal(args[0], t);
      case 'stop': return driven.stop(t);
      case 'mode': return driven.modeChange(args[0], args[1], t);
      case 'drive': return driven.drive(args[0], args[1], args[2], t);
      case 'pose': return driven.pose({ x: args[0], y: args[1], theta: args[2] }, t);
      case 'tick': return driven.tick(t);
      case 'new_link': return driven.newLink(t);
      case 'halt': return driven.halt(t);
      default: throw new Error(`no such input ${kind}`);
    }
  };
  return steps.map(([kind, t, args]) => {
    const records = feed(kind, t, args);
    return [records, driven.nextTick(t), driven.mode, driven.operator, driven.search];
  });
}"""


def rounded(value: Any) -> Any:
    """Floats to 9 places, through lists and records: both sides compute the same doubles up to
    rounding, and JSON makes no difference between 100 and 100.0."""
    if isinstance(value, list):
        return [rounded(item) for item in value]
    if isinstance(value, dict):
        return {key: rounded(item) for key, item in value.items()}
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return value
    return round(float(value), 9)


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/pilot") as opened:
        opened.evaluate(
            "async () => { window.control = await import('/static/js/core/control.js'); }"
        )
        yield opened


def run_js(page: Page, steps: list[Any], profile: str, robot: str = "turtlesim") -> Any:
    """The sequence run by pilot.js with the config a vehicle page for ``robot`` gets."""
    constants = to_json(control_config())
    freshness = to_json(page_protocol().goal_freshness)
    described = to_json(robot_config(PRESETS[robot]))
    return page.evaluate(RUN_JS, [steps, constants, freshness, described, profile])


@pytest.mark.parametrize("robot", ROBOTS)
@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_the_shared_sequences_give_the_same_records(page: Page, profile: str, robot: str) -> None:
    for name, steps in SEQUENCES.items():
        expected = run(steps, profile, robot)
        got = run_js(page, steps, profile, robot)
        for k, (want, have) in enumerate(zip(expected, got, strict=True)):
            # Field for field, in the log line's order.
            assert [list(r) for r in have[0]] == [list(r) for r in want[0]], (name, k)
            assert rounded(have) == rounded(want), (name, k, steps[k])


def test_a_burger_is_held_to_its_limits(page: Page) -> None:
    # The rule, not only the agreement: full stick on a TurtleBot3 Burger ramps at 2.5 m/s²
    # to 0.22 m/s, and the released stick stops it at once.
    steps = [
        ("mode", 0.0, ["manual", "ann"]),
        ("drive", 0.1, [1, 1.0, 0.0]),
        ("tick", 0.15, []),
        ("tick", 0.2, []),
        ("drive", 0.25, [2, 0.0, 0.0]),
    ]
    answers = run_js(page, steps, "default", "turtlebot3")
    speeds = [r["linear"] for answer in answers for r in answer[0] if r["ev"] == "twist"]
    assert speeds == pytest.approx([0.0, 2.5 * 0.05, 0.22, 0.0])


def test_goals_while_manual_are_dropped_why_manual_and_never_steer(page: Page) -> None:
    # The rule, not only the agreement: the page records what the agent records.
    steps = [
        ("pose", 0.0, [5.544445, 5.544445, 0.0]),
        ("mode", 0.1, ["manual", "ann"]),
        goal(1, 0.2),
        ("pose", 0.25, [5.544445, 5.544445, 0.0]),
        ("tick", 0.3, []),
    ]
    answers = run_js(page, steps, "default")
    assert answers[2][0] == [
        {"ev": "goal_dropped", "seq": 1, "frame": 101, "why": "manual", "t": 0.2}
    ]
    assert not any(r["ev"] == "twist" for answer in answers[2:] for r in answer[0])


def test_the_onboard_law_turns_to_a_face_and_searches_where_it_left(page: Page) -> None:
    # The rule, not only the agreement: a face right of centre turns the robot clockwise
    # (negative), and once it is gone the search turns right, then runs out and stops.
    steps = [
        ("pose", 0.0, [1.0, 3.0, 0.0]),
        goal(1, 0.05, x=560.0, y=240.0, box_h=60.0),
        *[("pose", round(0.05 + 0.1 * k, 2), [1.0, 3.0, 0.0]) for k in range(1, 80)],
    ]
    answers = run_js(page, steps, "onboard", "diffdrive")
    records = [r for answer in answers for r in answer[0]]
    first = next(r for r in records if r["ev"] == "twist")
    assert first["angular"] < 0 and first["seq"] == 1
    searches = [r for r in records if r["ev"] in ("search", "search_ended")]
    assert [r["ev"] for r in searches] == ["search", "search_ended"]
    assert searches[0]["side"] == "right" and searches[1]["why"] == "timed_out"
    last = records[-1]
    assert last["ev"] == "twist" and (last["linear"], last["angular"]) == (0, 0)
