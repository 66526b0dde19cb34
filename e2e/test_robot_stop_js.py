"""The relay's Stop robot (core/robot-stop.js): a burst of presses is one stop, told once."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.browser]


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/robot-stop", "robotStop") as opened:
        yield opened


def test_500_presses_while_the_robot_stands_are_one_stop_told_once(page: Page) -> None:
    told = page.evaluate(
        """() => {
             const stop = new robotStop.RobotStop();
             const told = [];
             // The first press stops a piloted robot; after it nothing moves the robot.
             for (let n = 0; n < 500; n += 1) {
               const message = stop.press('ann', `pressed ${n}`, n === 0);
               if (message !== null) told.push(message);
             }
             return told;
           }"""
    )
    assert told == [{"type": "robotStopped", "by": "ann", "reason": "pressed 0"}]


def test_a_press_once_something_moves_the_robot_again_is_a_new_stop(page: Page) -> None:
    told = page.evaluate(
        """() => {
             const stop = new robotStop.RobotStop();
             const reasons = [];
             const press = (reason, moving) => {
               const message = stop.press('ann', reason, moving);
               if (message !== null) reasons.push(message.reason);
             };
             press('first', true);
             press('again', false);
             press('at the wheel', true);  // an operator took the wheel since
             stop.clear();                  // piloting started again ...
             press('nobody watching', false);  // ... and stopped for want of a watcher
             return { reasons, standing: stop.standing };
           }"""
    )
    assert told["reasons"] == ["first", "at the wheel", "nobody watching"]
    assert told["standing"]["reason"] == "nobody watching"
