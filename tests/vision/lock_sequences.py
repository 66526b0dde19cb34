"""Scripted snapshot sequences for the target lock, run by lock.py here and by lock.js in a page.

A script is a list of events ``[kind, t, arg]`` (JSON-ready, so the page gets the very same):
``snapshot`` with the boxes found (each drawn from one of three tracks that wander, change size a
little and are now and then missed) and, as a fourth element, each box's look when given;
``click`` at a point; ``unlock``; ``search``: what the vehicle's pose says of its search for the
lost target (``left``, ``right``, ``timed_out``, or None when it does not search). The small
track vanishes twice: for 1.6 s (the lock searches, then finds it again) and for 4 s (the lock
is released).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from typing import Any

from app.vision import lock
from app.vision.window import Box

STEP_S = 0.05
DURATION_S = 20.0
# Track name -> (start x, start y, size): the large one is the default choice; the middle one is
# too large to be taken for the small one even by the whole-frame search.
TRACKS = {"large": (120, 150, 130), "small": (440, 200, 76), "middle": (300, 330, 125)}
SMALL_GONE = ((4.0, 5.6), (8.0, 12.0))
CLICKS_AT = (0.5, 12.5, 17.0)  # on the small track (never missed on these snapshots)
Event = list[Any]


# The rule itself on two faces, written out rather than computed by either side (lock.py and
# lock.js are each checked against it): each event and what must come of it -- for a snapshot
# the box chosen and the state, for a click [locked, state], for unlock [state]. The small face
# is clicked; its track is kept while the large face stays, grows, passes right over it, and
# while a third face a little larger than it (of a similar size) is in the picture; a snapshot
# that misses it chooses nothing, not the large face; a move with no overlap is followed to the
# nearest centre within reach; after Unlock the large face is the target again; a click on a box
# inside a larger one locks the inner one.
TWO_FACES: list[tuple[Event, list[Any]]] = [
    (["snapshot", 0.0, [[100, 100, 130, 130], [440, 200, 76, 76]]], [[100, 100, 130, 130], "none"]),
    (["click", 0.01, [478.0, 238.0]], [True, "locked"]),
    (
        ["snapshot", 0.05, [[104, 102, 132, 132], [446, 204, 78, 78]]],
        [[446, 204, 78, 78], "locked"],
    ),
    (
        ["snapshot", 0.1, [[90, 96, 170, 170], [250, 330, 98, 98], [450, 206, 76, 76]]],
        [[450, 206, 76, 76], "locked"],
    ),
    (
        ["snapshot", 0.15, [[400, 170, 130, 130], [456, 210, 76, 76]]],
        [[456, 210, 76, 76], "locked"],
    ),
    (["snapshot", 0.2, [[380, 170, 130, 130]]], [None, "lost"]),
    (
        ["snapshot", 0.25, [[250, 330, 98, 98], [380, 170, 130, 130], [470, 215, 76, 76]]],
        [[470, 215, 76, 76], "locked"],
    ),
    (
        ["snapshot", 0.3, [[250, 330, 98, 98], [546, 223, 60, 60], [100, 100, 130, 130]]],
        [[546, 223, 60, 60], "locked"],
    ),
    (["unlock", 0.31, None], ["none"]),
    (
        ["snapshot", 0.35, [[546, 223, 60, 60], [100, 100, 130, 130]]],
        [[100, 100, 130, 130], "none"],
    ),
    (["snapshot", 0.4, [[100, 100, 130, 130], [140, 120, 48, 48]]], [[100, 100, 130, 130], "none"]),
    (["click", 0.41, [164.0, 144.0]], [True, "locked"]),
    (
        ["snapshot", 0.45, [[101, 100, 130, 130], [142, 121, 48, 48]]],
        [[142, 121, 48, 48], "locked"],
    ),
]


# The lock holds through the vehicle's search, written out: the rule's numbers are a search of
# the whole frame after 1.0 s unseen (search_after_s) and a release after 3.0 s (release_after_s)
# -- unless the vehicle is searching for the target, and the onboard vehicle's search lasts up
# to 0.3 + 3π/1.6 = 6.19 s. Once its look is known, a box that does not overlap the target's is
# the target when it looks like it: at least 0.9 alike (min_likeness, the Bhattacharyya
# coefficient of the looks). A snapshot may give each box's look (a fourth element; two-bin
# looks here). The walker (60 px) is clicked, its
# look taken on the next snapshot; it leaves the view, the vehicle turns to search for it, and it
# comes back 5 s after it was last seen, farther (30 px: too small to be taken for it by size),
# beside the bystander (150 px, another look): it is locked again with no click, and followed
# by its look as the turning vehicle sweeps it across the frame. It leaves again; the bystander
# alone stays in view, never taken for it, and this time the vehicle's search runs out
# (timed_out): the lock lets go at the next snapshot, and the largest face is the target again.
WALKER, BYSTANDER = [300, 200, 60, 60], [500, 100, 150, 150]
WALKER_FAR = [100, 210, 30, 30]
WALKER_LOOK, WALKER_FAR_LOOK, BYSTANDER_LOOK = [0.98, 0.02], [0.95, 0.05], [0.1, 0.9]
THROUGH_SEARCH: list[tuple[Event, list[Any]]] = [
    (["snapshot", 0.0, [WALKER], [WALKER_LOOK]], [WALKER, "none"]),
    (["click", 0.01, [330.0, 230.0]], [True, "locked"]),
    (["snapshot", 0.05, [[304, 202, 60, 60]], [WALKER_LOOK]], [[304, 202, 60, 60], "locked"]),
    (["snapshot", 0.5, [], []], [None, "lost"]),
    (["search", 0.6, "left"], ["lost"]),
    (["snapshot", 1.2, [], []], [None, "searching"]),
    (["snapshot", 3.5, [], []], [None, "searching"]),  # past release_after_s: held
    (
        ["snapshot", 5.0, [WALKER_FAR, BYSTANDER], [WALKER_FAR_LOOK, BYSTANDER_LOOK]],
        [WALKER_FAR, "locked"],
    ),
    (["search", 5.05, None], ["locked"]),  # a goal came: the vehicle's search is over
    # The vehicle turns to it: the walker moves 300 px across the frame, ten times its size
    # (reach: 1), and is followed by its look.
    (
        ["snapshot", 5.1, [[400, 212, 30, 30], BYSTANDER], [WALKER_FAR_LOOK, BYSTANDER_LOOK]],
        [[400, 212, 30, 30], "locked"],
    ),
    (["snapshot", 5.5, [BYSTANDER], [BYSTANDER_LOOK]], [None, "lost"]),
    (["search", 5.6, "right"], ["lost"]),
    (["snapshot", 6.0, [BYSTANDER], [BYSTANDER_LOOK]], [None, "lost"]),
    (["snapshot", 9.0, [BYSTANDER], [BYSTANDER_LOOK]], [None, "searching"]),
    (["search", 11.2, "timed_out"], ["searching"]),
    (["snapshot", 11.25, [BYSTANDER], [BYSTANDER_LOOK]], [None, "none"]),
    (["snapshot", 11.3, [BYSTANDER], [BYSTANDER_LOOK]], [BYSTANDER, "none"]),
]
# The same without the vehicle's word: the lock lets go at 3.5 s, 3.45 s after the walker was
# last seen, and the walker coming back is not the target.
WITHOUT_SEARCH = [event for event, _ in THROUGH_SEARCH if event[0] != "search"]


# The click rule itself (near = 0.5 of a box's own size; a click window 0.6 of the shorter
# side), written out: [x, y, boxes, the box picked or None]. LARGE is 130 wide and tall, from 100
# to 230: half of it is 65 pixels; SMALL is 76 wide, from 440.
LARGE, SMALL = [100, 100, 130, 130], [440, 200, 76, 76]
NEAR_CLICKS: list[list[Any]] = [
    [230 + 65, 165, [LARGE], LARGE],  # on the limit, to the right
    [230 + 66, 165, [LARGE], None],
    [165, 100 - 65, [LARGE], LARGE],  # above
    [165, 100 - 66, [LARGE], None],
    [100 - 65, 230 + 65, [LARGE], LARGE],  # a corner, half of it either way
    [100 - 65, 230 + 66, [LARGE], None],
    # Each box in its own size: 50 pixels from a 200-pixel box (a quarter of it) beats 50 from
    # a 50-pixel one (the whole of it), whichever comes first.
    [250, 25, [[300, 0, 50, 50], [0, 0, 200, 200]], [0, 0, 200, 200]],
    [405, 238, [LARGE, SMALL], SMALL],  # 35 pixels left of SMALL: 0.46 of it
    [400, 238, [LARGE, SMALL], None],  # 40 pixels: 0.53 of it
    [228, 238, [SMALL, LARGE], LARGE],  # inside a box: that box, whatever it is near
    [150, 150, [LARGE, [130, 130, 40, 40]], [130, 130, 40, 40]],  # the smallest under it
]
# [x, y, width, height, the window searched or None]: a square 0.6 of the frame's shorter side
# (288 of 480), centred on the click, moved inside the frame; none for a click outside it.
CLICK_WINDOWS: list[list[Any]] = [
    [320, 240, 640, 480, [176, 96, 288, 288]],
    [10, 10, 640, 480, [0, 0, 288, 288]],
    [630, 470, 640, 480, [352, 192, 288, 288]],
    [700, 10, 640, 480, None],
    [10, -1, 640, 480, None],
]


def decisions(events: list[Event], outcomes: list[list[Any]]) -> list[list[Any]]:
    """What TWO_FACES states of each outcome of :func:`run` (or of lock.js's run)."""
    return [
        [o[2], o[3]] if kind == "snapshot" else o
        for (kind, *_), o in zip(events, outcomes, strict=True)
    ]


def script(seed: int) -> tuple[list[Event], list[dict[str, str]]]:
    """The events, and for each snapshot which track each of its boxes came from."""
    rng = random.Random(seed)
    where = {name: [float(x), float(y)] for name, (x, y, _) in TRACKS.items()}
    events: list[Event] = []
    owners: list[dict[str, str]] = []
    small_at: tuple[float, float] = (0.0, 0.0)
    for k in range(round(DURATION_S / STEP_S)):
        t = round(k * STEP_S, 3)
        boxes: list[Box] = []
        owner: dict[str, str] = {}
        for name, (_, _, size) in TRACKS.items():
            position = where[name]
            position[0] += rng.uniform(-4, 4)
            position[1] += rng.uniform(-3, 3)
            gone = name == "small" and any(a <= t < b for a, b in SMALL_GONE)
            missed = rng.random() < 0.1 and t not in CLICKS_AT
            if gone or missed:
                continue
            side = size + rng.randint(-6, 6)
            box = (round(position[0]), round(position[1]), side, side)
            boxes.append(box)
            owner[str(list(box))] = name
            if name == "small":
                small_at = (box[0] + side / 2, box[1] + side / 2)
        boxes.sort()
        events.append(["snapshot", t, [list(b) for b in boxes]])
        owners.append(owner)
        if t in CLICKS_AT:
            events.append(["click", t + 0.01, list(small_at)])
        if t == 15.0:
            events.append(["click", t + 0.01, [5.0, 5.0]])  # on no box: releases
        if t == 18.5:
            events.append(["unlock", t + 0.01, None])
    return events, owners


def _looks(boxes: list[Box], looks: list[list[float]]) -> Callable[[Box], list[float]]:
    """The look of each of a snapshot's boxes, as given with it."""
    table = dict(zip(boxes, looks, strict=True))
    return table.__getitem__


def run(events: list[Event], rule: lock.LockRule) -> list[list[Any]]:
    """What lock.py does with each event: for a snapshot [box asked, anywhere, box chosen,
    state, state changed]; for a click [locked, state]; for unlock and search [state]."""
    target = lock.TargetLock(rule)
    last: list[Box] = []
    out: list[list[Any]] = []
    robot_searching = False
    for kind, t, arg, *looks in events:
        if kind == "search":
            robot_searching = lock.robot_searching(arg)
            out.append([target.state])
        elif kind == "snapshot":
            last = [(b[0], b[1], b[2], b[3]) for b in arg]
            look_of = _looks(last, looks[0]) if looks else None
            query = target.query(t, robot_searching)
            chosen = lock.chooser(query, rule, look_of)(last)
            if chosen is not None and look_of is not None and target.needs_look(query):
                target.remember(look_of(chosen))
            changed = target.update(query, chosen, t, robot_searching)
            out.append(
                [
                    None if query is None else list(query.box),
                    None if query is None else query.anywhere,
                    None if chosen is None else list(chosen),
                    target.state,
                    changed,
                ]
            )
        elif kind == "click":
            out.append([target.lock(arg[0], arg[1], last, t), target.state])
        else:
            target.release()
            out.append([target.state])
    return out
