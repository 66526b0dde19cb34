"""The browser vehicle's manual override (manual.js) answers as the Python one does
(vehicle_agent/core/manual.py): the same scripted sequences, the same Twists, modes and dead-man
times. manual.js gets its numbers as the vehicle page does, from ``config.control``."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.protocol.control import control_config
from app.protocol.page import to_json
from app.server.serve import RunningServer
from e2e.helpers import module_page
from tests.vehicle_agent.core.manual_sequences import SEQUENCES, run
from vehicle_agent.core.control import PROFILES

pytestmark = [pytest.mark.browser]

CONSTANTS = to_json(control_config())

RUN_JS = """([events, profile, deadmanS]) => {
  const drive = new manual.ManualDrive(profile, deadmanS);
  return events.map(([kind, t, args]) => {
    let twist;
    if (kind === 'mode') twist = drive.setMode(args[0], args[1]);
    else if (kind === 'drive') twist = drive.drive(...args, t);
    else twist = drive.tick(t);
    const answer = twist === null ? null : [twist.linear, twist.angular];
    return [answer, drive.manual, drive.operator, drive.untilDeadman(t)];
  });
}"""


def rounded(value: Any) -> Any:
    """Floats to 9 places, through lists: both sides compute the same doubles up to rounding."""
    if isinstance(value, list):
        return [rounded(item) for item in value]
    return round(value, 9) if isinstance(value, float) else value


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/manual") as opened:
        yield opened


@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_scripted_sequences_take_the_same_decisions(page: Page, profile: str) -> None:
    constants = CONSTANTS["profiles"][profile]
    for name, events in SEQUENCES.items():
        expected: Any = run(events, PROFILES[profile])
        got = page.evaluate(RUN_JS, [events, constants, CONSTANTS["deadmanS"]])
        assert rounded(got) == rounded(expected), name


# The vehicle page's dead-man as vehicle.js builds it: its profile and `deadmanS` from the
# config the server embeds in /vehicle, with the times given. The last command comes at 1 s.
VEHICLE_PAGE_DEAD_MAN = """async (times) => {
  const html = await (await fetch('/vehicle')).text();
  const page = new DOMParser().parseFromString(html, 'text/html');
  const config = JSON.parse(page.getElementById('config').textContent);
  const { ControlLaw } = await import('/static/js/core/control.js');
  const profile = new ControlLaw(config.control).profiles[config.profile];
  const drive = new manual.ManualDrive(profile, config.control.deadmanS);
  drive.setMode('manual', 'ann');
  const moving = drive.drive(1, 1, 0, 1.0);
  const left = drive.untilDeadman(1.0);
  const ticks = times.map((t) => {
    const twist = drive.tick(t);
    return twist === null ? null : [twist.linear, twist.angular];
  });
  return { moving: [moving.linear, moving.angular], left, ticks };
}"""


def test_the_vehicle_page_stops_0_3_s_after_the_last_drive_command(page: Page) -> None:
    # The contract (docs/contracts.md) as a number: 0.3 s, not the constant the page is given.
    got = page.evaluate(VEHICLE_PAGE_DEAD_MAN, [1.1, 1.25, 1.29, 1.0 + 0.3, 1.31])
    assert got["moving"] == [PROFILES["default"].manual_linear, 0]
    assert got["left"] == pytest.approx(0.3)
    assert got["ticks"] == [None, None, None, [0, 0], None]
