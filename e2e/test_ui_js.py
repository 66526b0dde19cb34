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
    with module_page(server, browser, "ui") as page:
        assert page.evaluate(SHOW_TWICE_THEN_CHANGE) == [2, "x 2.00"]
