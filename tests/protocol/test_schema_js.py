"""The browser and Python judge data-channel messages alike.

Every sample of ``tests/protocol/samples.py`` goes through the pages' own receive path
(``peer.js`` ``serveChannel`` with ``schema.js`` and the schemas the server renders from
``app/protocol/channels.py``) in headless Chromium, and through ``channels.parse`` in Python.
The verdicts must agree, and a refusal must name the same field on both sides: a model changed
on one side only, or a schema keyword ``schema.js`` misreads, fails here.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Page

from app.protocol import channels
from tests.helpers.served_page import served_page
from tests.protocol.samples import SAMPLES

pytestmark = [pytest.mark.browser]

# A stand-in RTCDataChannel (an EventTarget with label, readyState and send) served by the real
# serveChannel; a handler per accepted type records what got through, send() the error replies.
RECEIVE_ALL = """async (samples) => {
  const { serveChannel } = await import('/static/js/net/peer.js');
  const { SCHEMAS } = await import('/static/js/config.js');
  const { acceptedTypes } = await import('/static/js/core/schema.js');
  const quiet = { info() {}, warn() {}, error() {} };
  return samples.map(({ label, role, text }) => {
    const channel = new EventTarget();
    channel.label = label;
    channel.readyState = 'open';
    const replies = [];
    channel.send = (reply) => replies.push(JSON.parse(reply));
    const handled = [];
    const schema = SCHEMAS[label][role];
    const types = acceptedTypes(schema).filter((t) => t !== 'error');
    const handlers = Object.fromEntries(types.map((t) => [t, (msg) => handled.push(msg)]));
    serveChannel(channel, handlers, quiet, schema);
    channel.dispatchEvent(new MessageEvent('message', { data: text }));
    return { handled: handled.length, replies };
  });
}"""


@pytest.fixture(scope="module")
def page() -> Iterator[Page]:
    with served_page() as opened:
        yield opened


def test_browser_and_python_agree_on_every_sample(page: Page) -> None:
    js: list[dict[str, Any]] = page.evaluate(
        RECEIVE_ALL, [{"label": s.label, "role": s.role, "text": s.text} for s in SAMPLES]
    )
    for sample, got in zip(SAMPLES, js, strict=True):
        python = channels.parse(sample.text, sample.label, sample.role)
        python_ok = not isinstance(python, channels.Refused)
        browser_ok = got["replies"] == []
        assert python_ok == browser_ok == sample.valid, (sample, python, got)
        if not sample.valid:
            [reply] = got["replies"]
            assert reply["type"] == "error"
            if sample.field is not None:
                assert isinstance(python, channels.Refused)
                assert f"'{sample.field}" in python.reason, python.reason
                assert f'field "{sample.field}' in reply["reason"], reply["reason"]
                assert reply["ref"] == python.ref
        elif '"type": "error"' not in sample.text:
            assert got["handled"] == 1, (sample, got)


def test_schema_js_refuses_a_keyword_it_does_not_know(page: Page) -> None:
    # A model that starts using, say, a regex pattern must fail loudly in the browser, not be
    # waved through by a validator that skips what it does not understand.
    error = page.evaluate(
        """async () => {
             const { validate } = await import('/static/js/core/schema.js');
             try { validate({ type: 'string', pattern: '^a' }, 'b'); return null; }
             catch (err) { return err.message; }
           }"""
    )
    assert error is not None and "pattern" in error
