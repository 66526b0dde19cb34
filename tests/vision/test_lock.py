"""The target lock's rule (app/vision/lock.py), sans I/O: clicks, association, lost and found.

The last test runs it the relay's way on the two-face scene, with the Python reference
detection and the tracker's window: the smaller face, once clicked, stays the target, and the
window follows it.
"""

from __future__ import annotations

import cv2
import pytest

from app.resources import OPERATIONS_SPEC
from app.vision import lock, reference, spec, window
from tests.vision import lock_sequences
from vehicle_agent.video import TwoFaceVideo

RULE = lock.LockRule()
LARGE = (100, 100, 130, 130)
SMALL = (440, 200, 76, 76)


def test_a_click_picks_the_smallest_box_under_it() -> None:
    inner = (130, 130, 40, 40)
    assert lock.pick(150, 150, [LARGE, inner]) == inner
    assert lock.pick(105, 105, [LARGE, inner]) == LARGE
    assert lock.pick(470, 230, [LARGE, SMALL]) == SMALL
    assert lock.pick(10, 10, [LARGE, SMALL]) is None


def test_association_prefers_overlap_then_the_nearest_centre_of_a_similar_size() -> None:
    moved = (446, 204, 78, 78)
    assert lock.associate(SMALL, [LARGE, moved], False, RULE) == moved
    # The large face overlapping the locked small one is not its track: too big.
    assert lock.associate(SMALL, [(420, 180, 130, 130)], False, RULE) is None
    # No overlap: the nearest centre within reach (one side of the locked box away).
    near, far = (510, 200, 76, 76), (600, 200, 76, 76)
    assert lock.associate(SMALL, [far, near], False, RULE) == near
    assert lock.associate(SMALL, [far], False, RULE) is None
    # Searching the whole frame, any similar box will do, nearest first.
    assert lock.associate(SMALL, [LARGE, far], True, RULE) == far


def test_lost_then_searching_then_released() -> None:
    target = lock.TargetLock(RULE)
    assert target.lock(470, 230, [LARGE, SMALL], now=0.0)
    query = target.query(0.1)
    assert query is not None and not query.anywhere
    assert target.update(query, None, 0.5) == "lost"
    assert target.update(target.query(0.6), None, 0.6) is None  # still lost: no news
    query = target.query(1.2)
    assert query is not None and query.anywhere
    assert target.update(query, None, 1.2) == "searching"
    found = (300, 300, 80, 80)
    assert target.update(target.query(1.3), found, 1.3) == "locked" and target.box == found
    assert target.update(target.query(4.4), None, 4.4) == "none"
    assert target.box is None and target.query(4.5) is None


def test_an_answer_to_an_older_lock_is_not_news() -> None:
    target = lock.TargetLock(RULE)
    target.lock(470, 230, [LARGE, SMALL], now=0.0)
    asked = target.query(0.0)
    target.release()
    assert target.update(asked, SMALL, 0.1) is None and target.state == "none"
    assert not target.lock(5, 5, [LARGE, SMALL], now=0.2)  # a click on no box releases
    assert target.state == "none"


def test_a_clicked_small_face_stays_the_target_beside_a_larger_one() -> None:
    events = [event for event, _ in lock_sequences.TWO_FACES]
    outcomes = lock_sequences.run(events, RULE)
    got = lock_sequences.decisions(events, outcomes)
    for i, ((event, want), have) in enumerate(zip(lock_sequences.TWO_FACES, got, strict=True)):
        assert have == want, (i, event)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_scripted_lock_follows_the_small_track_only(seed: int) -> None:
    events, owners = lock_sequences.script(seed)
    outcomes = lock_sequences.run(events, RULE)
    snapshot_outcomes = [
        o for (kind, _, _), o in zip(events, outcomes, strict=True) if kind == "snapshot"
    ]
    states = [o[3] for o in snapshot_outcomes]
    chosen_owners = [
        owner.get(str(o[2]))
        for owner, o in zip(owners, snapshot_outcomes, strict=True)
        if o[0] is not None and o[2] is not None
    ]
    # While locked, every box chosen belongs to the small track.
    assert chosen_owners and set(chosen_owners) == {"small"}
    # Both disappearances were noticed: a search, and a release after the long one.
    assert "searching" in states and "lost" in states
    changes = [o[4] for o in snapshot_outcomes if o[4] is not None]
    assert changes.count("none") == 1, changes


def test_the_smaller_face_stays_the_target_in_the_two_face_scene() -> None:
    op = spec.load_spec(OPERATIONS_SPEC).op("face")
    assert isinstance(op, spec.CascadeOperation)
    video = TwoFaceVideo()
    tracker = window.Tracker(op.params.full_scan_every)
    target = lock.TargetLock(RULE)
    scans: list[window.Scan] = []
    for i in range(0, 72, 2):  # 2.4 s of the scene's drift
        rgba = cv2.cvtColor(video.render(i), cv2.COLOR_RGB2RGBA)
        t = i / video.fps
        query = target.query(t)
        choose = lock.chooser(query, RULE)
        found, scan = window.step(
            tracker, lambda box, rgba=rgba: reference.detect(op, rgba, around=box), choose
        )
        chosen = choose(found.boxes)
        target.update(query, chosen, t)
        scans.append(scan)
        assert chosen is not None
        truth = video.small_centre(i) if i > 0 else video.face_centre(i)
        assert lock.contains(chosen, *truth), (i, chosen, truth)
        if scan == "window":  # around the small face: the large one was not even searched
            assert found.boxes == [chosen], (i, found.boxes)
        if i == 0:  # the default choice was the large face: click the small one
            assert target.lock(*video.small_centre(0), found.boxes, t)
            tracker.reset()
    # From the click on, the window followed the small face on every snapshot but the tracker's
    # periodic full scans: it never lost it to a full scan.
    cadence = ["full"] + ["window"] * (op.params.full_scan_every - 1)
    assert scans == ["full", *(cadence * 2)[: len(scans) - 1]], scans
