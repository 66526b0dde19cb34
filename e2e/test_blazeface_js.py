"""BlazeFace decoding in the relay's worker (core/blazeface.js) follows the rule stated in
tests/vision/blazeface_sequences.py and agrees with its Python twin (app/vision/blazeface.py)
on the same seeded model outputs."""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import pytest
from playwright.sync_api import Browser, Page

from app.server.serve import RunningServer
from e2e.helpers import module_page
from tests.vision import blazeface_sequences as seq

pytestmark = [pytest.mark.browser]

# The page's side of blazeface_sequences.run. The cases cross as one JSON string: Playwright
# serializes an argument value by value, seconds for a seed's few hundred thousand numbers.
RUN_JS = """(text) => JSON.parse(text).map((c) => {
  const fit = blazeface.letterbox(c.region, c.input);
  const faces = blazeface.decode(
    c.scores, c.raw, blazeface.anchors(c.input, c.layers), fit, c.threshold);
  return blazeface.suppress(faces, c.overlap, c.minSize)
    .map((f) => [f.box, f.score, f.keypoints]);
})"""

RULE_JS = """(rule) => ({
  anchors: rule.anchors.map(([layers, size]) => {
    const c = blazeface.anchors(size, layers);
    return [c.length, c[0], c[c.length - 1]];
  }),
  letterbox: rule.letterbox.map(([region, size]) => {
    const fit = blazeface.letterbox(region, size);
    return [fit.scale, fit.width, fit.height];
  }),
  passes: rule.passes.map(([args]) => blazeface.passes(...args)),
  around: rule.around.map(([args]) => blazeface.around(...args)),
  decode: rule.decode.map(([scores, raw, layers, size, region, threshold]) =>
    blazeface.decode(scores, raw, blazeface.anchors(size, layers),
      blazeface.letterbox(region, size), threshold)
      .map((f) => [f.box, f.score, f.keypoints[0]])),
  suppress: rule.suppress.map(([boxes, scores, overlap, minSize]) => {
    const faces = boxes.map((box, i) => ({ box, score: scores[i], keypoints: [] }));
    return blazeface.suppress(faces, overlap, minSize).map((k) => faces.indexOf(k));
  }),
})"""


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/blazeface") as opened:
        yield opened


def test_the_js_twin_follows_the_rule(page: Page) -> None:
    rule = seq.RULE
    got: dict[str, Any] = page.evaluate(RULE_JS, rule)
    assert got["anchors"] == [[count, first, last] for _, _, count, first, last in rule["anchors"]]
    assert got["letterbox"] == [pytest.approx(want) for *_, want in rule["letterbox"]]
    assert got["passes"] == [want for _, want in rule["passes"]]
    assert got["around"] == [want for _, want in rule["around"]]
    assert got["decode"] == [case[-1] for case in rule["decode"]]
    assert got["suppress"] == [case[-1] for case in rule["suppress"]]


def test_seeded_model_outputs_decode_the_same_on_both_sides(page: Page) -> None:
    for seed in (1, 2, 3):
        cases = seq.script(seed)
        got = page.evaluate(RUN_JS, json.dumps(cases))
        want = [seq.run(case) for case in cases]
        assert sum(len(w) for w in want) > len(cases)  # faces kept, so agreeing means something
        for i, (have, expected) in enumerate(zip(got, want, strict=True)):
            assert [f[0] for f in have] == [f[0] for f in expected], (seed, i)
            for (_, s1, k1), (_, s2, k2) in zip(have, expected, strict=True):
                assert seq.close(s1, s2), (seed, i)
                flat1 = [v for p in k1 for v in p]
                flat2 = [v for p in k2 for v in p]
                assert all(seq.close(a, b) for a, b in zip(flat1, flat2, strict=True))
