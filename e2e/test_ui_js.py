"""ui.js, the role pages' DOM helpers, in a real page."""

from __future__ import annotations

import pytest
from playwright.sync_api import Browser

from app.server.serve import RunningServer
from e2e.helpers import module_page

pytestmark = [pytest.mark.e2e, pytest.mark.browser]

# Mutations of a probe element while show() writes it: the same text twice, then a new one.
SHOW_TWICE_THEN_CHANGE = """() => {
  const el = document.createElement('span');
  el.dataset.testid = 'probe';
  document.body.append(el);
  let records = 0;
  new MutationObserver((found) => { records += found.length; })
    .observe(el, { childList: true, characterData: true, subtree: true });
  ui.show('probe', 'x 1.00');
  ui.show('probe', 'x 1.00');
  ui.show('probe', 'x 2.00');
  return new Promise((resolve) => setTimeout(() => resolve([records, el.textContent]), 0));
}"""


def test_show_leaves_unchanged_text_alone(server: RunningServer, browser: Browser) -> None:
    # A still turtle's pose arrives 60 times a second with the same text: rewriting it anyway
    # made the vehicle page lay out and repaint at 60 Hz (0.3 of a core on an idle page).
    with module_page(server, browser, "view/ui") as page:
        assert page.evaluate(SHOW_TWICE_THEN_CHANGE) == [2, "x 2.00"]


# Ten calls in a row through a 100 ms throttle, then a wait: when the function ran, and the
# state it saw each time. (In a row, not spaced by timers: a loaded machine stretches timers.)
THROTTLE_TEN_CALLS = """async () => {
  let state = 0;
  const seen = [];
  const start = performance.now();
  const shown = ui.throttle(100, () => seen.push([performance.now() - start, state]));
  for (let i = 1; i <= 10; i += 1) {
    state = i;
    shown();
  }
  await new Promise((resolve) => setTimeout(resolve, 250));
  return seen;
}"""


def test_throttle_runs_at_once_then_at_most_once_a_period_with_the_last_state(
    server: RunningServer, browser: Browser
) -> None:
    # The figures and the turtle's map are redrawn through it: a person must see the last pose
    # when the turtle stops, not the one before it.
    with module_page(server, browser, "view/ui") as page:
        seen = page.evaluate(THROTTLE_TEN_CALLS)
    assert [state for _, state in seen] == [1, 10], seen
    # Deferred to the end of the period (less a millisecond: the page clock is coarse).
    assert seen[0][0] < 50 and seen[1][0] >= 99, seen
