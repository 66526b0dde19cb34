"""The relay's target lock (lock.js) follows the rule and agrees with the Python one
(app/vision/lock.py).

The relay page and its vision worker read the rule app/protocol defines; lock.js takes the
decisions written out in tests/vision/lock_sequences.py (``TWO_FACES``), and those of lock.py on
the same scripted snapshot sequences and the same grid of boxes.
"""

from __future__ import annotations

import itertools
import json
import random
from collections.abc import Iterator
from typing import Any
from urllib.parse import parse_qs, urlsplit

import pytest
from playwright.sync_api import Browser, Page

from app.protocol.page import page_protocol, to_json
from app.server.serve import RunningServer
from app.vision import lock
from app.vision.window import Box
from e2e.helpers import module_page
from tests.vision import lock_sequences

pytestmark = [pytest.mark.browser]

PAGE_RULE = to_json(page_protocol().lock)


def page_rule(rule: dict[str, float]) -> lock.LockRule:
    return lock.LockRule(
        search_after_s=rule["searchAfterS"],
        release_after_s=rule["releaseAfterS"],
        max_scale=rule["maxScale"],
        reach=rule["reach"],
        near=rule["near"],
        click_search=rule["clickSearch"],
        look_bins=tuple(rule["lookBins"]),
        min_likeness=rule["minLikeness"],
    )


RULE = page_rule(PAGE_RULE)

# The page's side of lock_sequences.run, event for event.
RUN_JS = """([events, rule]) => {
  const target = new lock.TargetLock(rule);
  let last = [];
  let robotSearching = false;
  return events.map(([kind, t, arg, looks]) => {
    if (kind === 'search') {
      robotSearching = lock.robotSearching(arg);
      return [target.state];
    }
    if (kind === 'snapshot') {
      last = arg;
      const lookOf = looks === undefined ? null : (box) => looks[last.indexOf(box)];
      const query = target.query(t, robotSearching);
      const chosen = lock.chooser(query, rule, lookOf)(last);
      if (chosen !== null && lookOf !== null && target.needsLook(query)) {
        target.remember(lookOf(chosen));
      }
      const changed = target.update(query, chosen, t, robotSearching);
      return [query && query.box, query && query.anywhere, chosen, target.state, changed];
    }
    if (kind === 'click') return [target.lock(arg[0], arg[1], last, t), target.state];
    target.release();
    return [target.state];
  });
}"""


# lock.js's rules, each reached the way the relay's worker reaches it: a click through
# TargetLock.lock (the box it holds, null when it released), the click's window through lockAt
# (the window it hands the search), the track's box and the look's through chooser.
PUBLIC_JS = """() => {
  window.picked = (x, y, boxes, rule) => {
    const target = new lock.TargetLock(rule);
    target.lock(x, y, boxes, 0);
    return target.box;
  };
  window.searchedAt = (x, y, width, height, rule) => {
    let asked = null;
    const search = (window) => {
      asked = window;
      return [];
    };
    lock.lockAt(new lock.TargetLock(rule), x, y, [], search, width, height, 0);
    return asked;
  };
  window.continued = (locked, boxes, anywhere, rule) =>
    lock.chooser({ box: locked, anywhere, look: null }, rule)(boxes);
  // A target whose box is far from every box and of no box's size, while the vehicle searches:
  // the box most like its look, of any size, anywhere.
  window.mostLike = (look, boxes, lookOf, rule) =>
    lock.chooser(
      { box: [-1e6, -1e6, 1, 1], anywhere: true, look, anySize: true },
      rule,
      lookOf,
    )(boxes);
}"""


@pytest.fixture
def page(server: RunningServer, browser: Browser) -> Iterator[Page]:
    with module_page(server, browser, "core/lock") as opened:
        opened.evaluate(PUBLIC_JS)
        yield opened


def test_the_rule_reaches_the_page_from_app_protocol(
    server: RunningServer, browser: Browser
) -> None:
    # The relay page's modules (its snapshot loop) and its vision worker (which chooses the
    # locked box) hold the rule app/protocol defines, each read as it reads it: the page's from
    # its embedded config, the worker's from the query string the page started it with.
    relay = browser.new_page()
    try:
        # The vision worker, not the video forward's (worker/forward-worker.js).
        with relay.expect_worker(lambda worker: "vision-worker" in worker.url) as started:
            relay.goto(server.url + "/relay")
        in_page = relay.evaluate("async () => (await import('/static/js/config.js')).PROTOCOL.lock")
        query = parse_qs(urlsplit(started.value.url).query)
        in_worker = json.loads(query["protocol"][0])["lock"]
    finally:
        relay.close()
    assert page_rule(in_page) == lock.LockRule()
    assert page_rule(in_worker) == lock.LockRule()


def test_a_clicked_small_face_stays_the_target_beside_a_larger_one(page: Page) -> None:
    # The rule itself, as written out in lock_sequences.TWO_FACES (not lock.py's answers).
    events = [event for event, _ in lock_sequences.TWO_FACES]
    got = lock_sequences.decisions(events, page.evaluate(RUN_JS, [events, PAGE_RULE]))
    for i, ((event, want), have) in enumerate(zip(lock_sequences.TWO_FACES, got, strict=True)):
        assert have == want, (i, event)


def test_the_lock_holds_through_the_vehicles_search(page: Page) -> None:
    # The rule as written out in lock_sequences.THROUGH_SEARCH (search after 1.0 s unseen,
    # release after 3.0 s unless the vehicle searches; its search lasts up to 6.19 s).
    assert (RULE.search_after_s, RULE.release_after_s, RULE.min_likeness) == (1.0, 3.0, 0.9)
    events = [event for event, _ in lock_sequences.THROUGH_SEARCH]
    got = lock_sequences.decisions(events, page.evaluate(RUN_JS, [events, PAGE_RULE]))
    for i, ((event, want), have) in enumerate(zip(lock_sequences.THROUGH_SEARCH, got, strict=True)):
        assert have == want, (i, event)
    # The same snapshots with no word of a search: released at 3.5 s, as lock.py does.
    alone = lock_sequences.WITHOUT_SEARCH
    assert page.evaluate(RUN_JS, [alone, PAGE_RULE]) == lock_sequences.run(alone, RULE)
    assert page.evaluate(
        "() => ['left', 'right', 'timed_out', null, undefined].map(lock.robotSearching)"
    ) == [True, True, False, False, False]


def test_looks_likeness_and_recognition_agree_with_python(page: Page) -> None:
    rng = random.Random(11)

    def look() -> list[float]:
        counts = [rng.random() ** 3 for _ in range(64)]
        return [c / sum(counts) for c in counts]

    looks = [look() for _ in range(12)]
    boxes = [[rng.uniform(-50, 600), rng.uniform(-50, 450), rng.uniform(5, 200), 80] for _ in looks]
    # Each look against each, one box at a time: recognised with the least likeness set just
    # below what lock.py measures, not just above it, so both measure the same to 1e-9.
    pairs = [[a, b, lock.likeness(a, b)] for a in looks for b in looks]
    assert any(0.0 < like < RULE.min_likeness for _, _, like in pairs)
    js: dict[str, Any] = page.evaluate(
        """([looks, boxes, rule, pairs]) => ({
             likeness: pairs.map(([a, b, like]) => [like - 1e-9, like + 1e-9].map(
               (minLikeness) => mostLike(b, [[0, 0, 10, 10]], () => a, { ...rule, minLikeness })
                 !== null)),
             recognised: looks.map((target) => mostLike(
               target, boxes, (box) => looks[boxes.indexOf(box)], rule)),
             rects: boxes.map((box) => lock.lookRect(box, 640, 480)),
           })""",
        [looks, boxes, PAGE_RULE, pairs],
    )
    assert js["likeness"] == [[True, False]] * len(pairs)
    table = {tuple(b): look for b, look in zip(boxes, looks, strict=True)}
    want = [
        lock.recognise(
            [tuple(b) for b in boxes],  # type: ignore[misc]
            lambda box, target=target: lock.likeness(table[box], target),
            RULE,
        )
        for target in looks
    ]
    assert js["recognised"] == [None if w is None else list(w) for w in want]
    assert [[r["x"], r["y"], r["width"], r["height"]] for r in js["rects"]] == [
        list(lock.look_rect(tuple(b), 640, 480))  # type: ignore[arg-type]
        for b in boxes
    ]


def test_scripted_sequences_take_the_same_decisions(page: Page) -> None:
    for seed in (1, 2, 3):
        events, _ = lock_sequences.script(seed)
        expected = lock_sequences.run(events, RULE)
        got = page.evaluate(RUN_JS, [events, PAGE_RULE])
        # Every kind of decision occurs, so agreeing means something.
        snapshots = [
            o for (kind, _, _), o in zip(events, expected, strict=True) if kind == "snapshot"
        ]
        assert {o[3] for o in snapshots} == {"none", "locked", "lost", "searching"}
        assert len(got) == len(expected)
        for i, (event, want, have) in enumerate(zip(events, expected, got, strict=True)):
            assert have == want, (seed, i, event, want, have)


def test_pick_overlap_and_association_on_a_grid(page: Page) -> None:
    rng = random.Random(7)

    def box() -> Box:
        side = rng.choice([40, 60, 76, 80, 100, 130])
        return (rng.randint(0, 560), rng.randint(0, 400), side, side + rng.randint(-4, 4))

    locked_boxes = [box() for _ in range(12)]
    sets = [[box() for _ in range(rng.randint(0, 5))] for _ in range(40)]
    sets += [[b, b] for b in locked_boxes[:3]]  # ties: the first wins
    points = [(rng.uniform(0, 640), rng.uniform(0, 480)) for _ in range(40)]
    cases = list(itertools.product(locked_boxes, sets))
    js: dict[str, Any] = page.evaluate(
        """([cases, sets, points, rule]) => ({
             associate: cases.map(([l, boxes]) => [false, true].map(
               (anywhere) => continued(l, boxes, anywhere, rule))),
             pick: points.flatMap(([x, y]) => sets.map((boxes) => picked(x, y, boxes, rule))),
             lockable: cases.map(([l, boxes]) => lock.lockable([l], boxes)),
             window: points.map(([x, y]) => searchedAt(x, y, 640, 480, rule)),
           })""",
        [cases, sets, points, PAGE_RULE],
    )

    def listed(b: Box | None) -> list[int] | None:
        return None if b is None else list(b)

    want_associate = [
        [listed(lock.associate(locked, boxes, anywhere, RULE)) for anywhere in (False, True)]
        for locked, boxes in cases
    ]
    assert js["associate"] == want_associate
    assert any(a != [None, None] for a in want_associate)
    assert any(a[0] is None and a[1] is not None for a in want_associate)
    # Some tracks are continued by overlap, some by the nearest centre.
    assert any(lock.overlap(locked, b) > 0 for locked, boxes in cases for b in boxes)
    assert any(
        a[0] is not None and lock.overlap(locked, tuple(a[0])) == 0  # type: ignore[arg-type]
        for (locked, _), a in zip(cases, want_associate, strict=True)
    )
    want_pick = [listed(lock.pick(x, y, boxes, RULE.near)) for x, y in points for boxes in sets]
    assert js["pick"] == want_pick and any(p is not None for p in want_pick)
    # Some of the picks are near a box, not in it.
    assert any(
        p is not None and not lock.contains(tuple(p), x, y)  # type: ignore[arg-type]
        for (x, y), p in zip([(x, y) for x, y in points for _ in sets], want_pick, strict=True)
    )
    # And some near several boxes and in none, where the nearest in its own size wins.
    assert any(
        not any(lock.contains(b, x, y) for b in boxes)
        and sum(lock.gap(b, x, y) <= RULE.near for b in boxes) > 1
        for x, y in points
        for boxes in sets
    )
    want_lockable = [[list(b) for b in lock.lockable([locked], boxes)] for locked, boxes in cases]
    assert js["lockable"] == want_lockable
    assert {len(v) for v in want_lockable} > {1}  # some candidates kept, and some dropped
    want_window = [listed(lock.click_window(x, y, 640, 480, RULE.click_search)) for x, y in points]
    assert js["window"] == want_window


def test_near_clicks_and_click_windows_follow_the_rule(page: Page) -> None:
    # The rule itself, as written out in lock_sequences (not lock.py's answers).
    got = page.evaluate(
        """([clicks, windows, rule]) => [
             clicks.map(([x, y, boxes]) => picked(x, y, boxes, rule)),
             windows.map(([x, y, w, h]) => searchedAt(x, y, w, h, rule)),
           ]""",
        [lock_sequences.NEAR_CLICKS, lock_sequences.CLICK_WINDOWS, PAGE_RULE],
    )
    assert got == [
        [want for *_, want in lock_sequences.NEAR_CLICKS],
        [want for *_, want in lock_sequences.CLICK_WINDOWS],
    ]


# A click at the tiny face's centre beside two faces, the search answering with the boxes given
# (recording the windows it was asked); then clicks on the same and on another target.
LOCK_AT_JS = """([rule, large, small, tiny]) => {
  const target = new lock.TargetLock(rule);
  const windows = [];
  const search = (found) => (window) => { windows.push(window); return found; };
  const seen = [];
  const step = (how) => seen.push([how, target.state, target.box, target.fine]);
  step(lock.lockAt(target, 405, 238, [large, small], search([]), 640, 480, 0));
  step(lock.lockAt(target, 409, 88, [large, small], search([small, tiny]), 640, 480, 0.1));
  step(lock.lockAt(target, 409, 88, [tiny], null, 640, 480, 0.3));
  const query = target.query(0.35);
  step(lock.lockAt(target, 470, 230, [small], null, 640, 480, 0.4));
  step(lock.lockAt(target, 600, 400, [large], search([small]), 640, 480, 0.5));
  return { seen, windows, fineQuery: query.fine };
}"""


def test_a_click_near_no_box_searches_its_window_as_lock_py_does(page: Page) -> None:
    large, small, tiny = [100, 100, 130, 130], [440, 200, 76, 76], [389, 68, 40, 40]
    got = page.evaluate(LOCK_AT_JS, [PAGE_RULE, large, small, tiny])
    assert got["seen"] == [
        ["picked", "locked", small, False],  # near SMALL: no search
        ["searched", "locked", tiny, True],  # near nothing: the click's window searched
        ["picked", "locked", tiny, True],  # the same target: still followed at full resolution
        ["picked", "locked", small, False],
        [None, "none", None, False],  # nothing found near the click: released
    ]
    # (600, 400): 600 - 144 would leave the frame, 640 - 288 keeps it inside.
    assert got["windows"] == [[265, 0, 288, 288], [352, 192, 288, 288]]
    assert got["fineQuery"] is True


def test_the_boxes_shown_are_the_followed_one_and_the_candidates(
    server: RunningServer, browser: Browser
) -> None:
    # What the client draws (core/shown-boxes.js): the target the autopilot follows (the largest
    # box, or the locked one), and every other box a click may lock -- the snapshot's others and
    # those of the last full scan that are not the same face seen earlier.
    large, moved, small = [100, 100, 130, 130], [104, 102, 132, 132], [440, 200, 76, 76]
    cases = [
        # Between full scans: the window found the tracked face, the full scan had both.
        {"boxes": [moved], "target": {"x": 170, "y": 168}, "candidates": [large, small]},
        # A full scan: both faces, the larger tracked.
        {"boxes": [large, small], "target": {"x": 165, "y": 165}, "candidates": [large, small]},
        # The small face locked, found in its window.
        {"boxes": [small], "target": {"x": 478, "y": 238}, "locked": small, "candidates": [large]},
        # The locked face not found on this snapshot: nothing is followed.
        {"boxes": [large], "target": None, "locked": None, "candidates": [large, small]},
        None,
    ]
    with module_page(server, browser, "core/shown-boxes", "shown") as page:
        got = page.evaluate("(cases) => cases.map((d) => shown.shownBoxes(d))", cases)

    def kinds(boxes: list[dict[str, Any]]) -> list[tuple[list[int], str]]:
        return [([b["x"], b["y"], b["w"], b["h"]], b["kind"]) for b in boxes]

    assert [kinds(boxes) for boxes in got] == [
        [(moved, "tracked"), (small, "candidate")],
        [(large, "tracked"), (small, "candidate")],
        [(small, "locked"), (large, "candidate")],
        [(large, "candidate"), (small, "candidate")],
        [],
    ]
