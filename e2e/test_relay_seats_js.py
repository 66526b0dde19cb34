"""The relay's seats (core/relay-seats.js): one vehicle served and one client at the wheel, each
freed only by the peer that holds it; the wheel's refusals, and its drive numbering."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.browser]


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/relay-seats", "seats") as opened:
        yield opened


def test_a_departure_frees_only_the_seats_the_peer_held(page: Page) -> None:
    # Issue 37: a second vehicle that came and went took the first one's place with it.
    got: dict[str, Any] = page.evaluate(
        """() => {
          const vehicle = new seats.Seat('the relay');
          const wheel = new seats.OperatorSeat();
          const seen = [];
          const both = () => [vehicle.holder, wheel.holder];
          seen.push(vehicle.claim('v1'), wheel.takeOver('c1'));
          seen.push(vehicle.claim('v2'), both());
          for (const name of ['v2', 'c2', 'v1', 'c1']) {
            seen.push([name, vehicle.release(name), wheel.leave(name), ...both()]);
          }
          seen.push(vehicle.claim('v2'), both());
          return seen;
        }"""
    )
    assert got[:2] == [None, {"changed": True}]
    refusal, held = got[2], got[3]
    assert "v1" in refusal and held == ["v1", "c1"]
    assert got[4:8] == [
        ["v2", False, False, "v1", "c1"],  # never held anything: nothing goes
        ["c2", False, False, "v1", "c1"],
        ["v1", True, False, None, "c1"],  # the vehicle seat, and only it
        ["c1", False, True, None, None],  # the wheel, and only it
    ]
    assert got[8:] == [None, ["v2", None]]


def test_one_client_drives_at_a_time_and_each_operator_numbers_from_one(page: Page) -> None:
    got: list[Any] = page.evaluate(
        """() => {
          const wheel = new seats.OperatorSeat();
          const cmd = { linear: 0.5, angular: -0.25 };
          return [
            wheel.drive('c1', cmd), wheel.handBack('c1'), wheel.modeMessage(),
            wheel.takeOver('c1'), wheel.takeOver('c1'), wheel.takeOver('c2'),
            wheel.drive('c2', cmd), wheel.handBack('c2'),
            wheel.drive('c1', cmd), wheel.drive('c1', cmd), wheel.modeMessage('because'),
            wheel.handBack('c1'), wheel.takeOver('c2'), wheel.drive('c2', cmd),
          ];
        }"""
    )
    (
        no_drive,
        no_hand_back,
        auto,
        taken,
        again,
        busy,
        not_yours,
        not_yours_back,
        first,
        second,
        manual,
        handed,
        taken2,
        renumbered,
    ) = got
    assert "take over" in no_drive["refused"] and "nobody" in no_hand_back
    assert auto == {"type": "mode", "mode": "auto", "operator": None}
    assert taken == {"changed": True} and again == {"changed": False}
    assert "c1" in busy["refused"] and "c1" in not_yours["refused"] and "c1" in not_yours_back
    drive = {"type": "drive", "linear": 0.5, "angular": -0.25}
    assert first == {"drive": {**drive, "seq": 1}} and second == {"drive": {**drive, "seq": 2}}
    assert manual == {"type": "mode", "mode": "manual", "operator": "c1", "reason": "because"}
    assert handed is None and taken2 == {"changed": True}
    assert renumbered == {"drive": {**drive, "seq": 1}}


def test_a_stop_takes_the_wheel_back_and_the_next_operator_numbers_from_one(page: Page) -> None:
    got: list[Any] = page.evaluate(
        """() => {
          const wheel = new seats.OperatorSeat();
          const cmd = { linear: 1, angular: 0 };
          const seen = [wheel.takeBack()];
          wheel.takeOver('c1');
          wheel.drive('c1', cmd);
          seen.push(wheel.takeBack(), wheel.holder, wheel.drive('c1', cmd));
          seen.push(wheel.takeOver('c1'), wheel.drive('c1', cmd));
          return seen;
        }"""
    )
    nobody, taken_from, holder, refused, again, drive = got
    assert nobody is None and taken_from == "c1" and holder is None
    assert "take over" in refused["refused"]
    assert again == {"changed": True} and drive["drive"]["seq"] == 1


def test_nobody_watching_is_said_once_when_the_last_watching_client_goes(page: Page) -> None:
    # The rule: a client watches while it is in the room and its link has not dropped; each
    # change answers true only when it left nobody watching where somebody was.
    got: list[Any] = page.evaluate(
        """() => {
          const w = new seats.Watchers();
          const seen = [];
          const step = (what, answer) => seen.push([what, answer, w.names]);
          step('c1 and c2 join', w.room(['c1', 'c2']));
          step('c1 link up', w.linkUp('c1'));
          step('c1 link drops', w.linkDown('c1'));
          step('c2 leaves', w.room(['c1']));
          step('again: nobody left to go', w.room(['c1']));
          step('c1 link back', w.linkUp('c1'));
          step('c1 leaves', w.room([]));
          step('c3 joins', w.room(['c3']));
          step('c4 drops before joining', w.linkDown('c4'));
          step('c3 link drops', w.linkDown('c3'));
          step('c3 link drops again', w.linkDown('c3'));
          step('c3 leaves, c5 joins', w.room(['c5']));
          step('c3 link back, not in the room', w.linkUp('c3'));
          return seen;
        }"""
    )
    assert got == [
        ["c1 and c2 join", False, ["c1", "c2"]],
        ["c1 link up", None, ["c1", "c2"]],
        ["c1 link drops", False, ["c2"]],
        ["c2 leaves", True, []],  # c1 is in the room, but its link dropped
        ["again: nobody left to go", False, []],
        ["c1 link back", None, ["c1"]],
        ["c1 leaves", True, []],
        ["c3 joins", False, ["c3"]],
        ["c4 drops before joining", False, ["c3"]],
        ["c3 link drops", True, []],
        ["c3 link drops again", False, []],
        ["c3 leaves, c5 joins", False, ["c5"]],
        ["c3 link back, not in the room", None, ["c5"]],
    ]
