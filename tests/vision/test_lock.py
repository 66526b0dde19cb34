"""The target lock's rule (app/vision/lock.py), sans I/O: clicks, association, lost and found.

The last tests run it the relay's way on the two-face scene, with the Python reference
detection and the tracker's window: the smaller face, once clicked, stays the target, and the
window follows it; the tiny face the reduced scan cannot find is locked by a click (the
full-resolution search around it) and followed at full resolution.
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import pytest

from app.diffdrive.arena import ARENA, Pose2D, facing
from app.diffdrive.camera import Pinhole, Renderer
from app.diffdrive.robot import CAMERA_HFOV, RobotState
from app.diffdrive.sim import Placed, Scene
from app.resources import OPERATIONS_SPEC
from app.vision import lock, reference, spec, window
from tests.vision import lock_sequences
from tests.vision.relay_steps import RelaySteps
from vehicle_agent.video import TwoFaceVideo

RULE = lock.LockRule()
LARGE = (100, 100, 130, 130)
SMALL = (440, 200, 76, 76)


def test_a_click_picks_the_smallest_box_under_it() -> None:
    inner = (130, 130, 40, 40)
    assert lock.pick(150, 150, [LARGE, inner], RULE.near) == inner
    assert lock.pick(105, 105, [LARGE, inner], RULE.near) == LARGE
    assert lock.pick(470, 230, [LARGE, SMALL], RULE.near) == SMALL
    assert lock.pick(10, 10, [LARGE, SMALL], RULE.near) is None


def test_a_click_near_a_box_picks_it_within_half_its_size() -> None:
    # The rule (app/protocol/lock.py), as lock_sequences writes it out: a click outside every
    # box picks the box it is nearest to in that box's own size, when within half its width to
    # the side and half its height above or below.
    assert RULE.near == 0.5
    for x, y, boxes, want in lock_sequences.NEAR_CLICKS:
        got = lock.pick(x, y, [tuple(b) for b in boxes], RULE.near)
        assert got == (None if want is None else tuple(want)), (x, y, boxes)


def test_the_boxes_a_click_may_lock_are_the_snapshots_and_the_unseen_candidates() -> None:
    # Between full scans the snapshot found only the tracked face; the last full scan's box of
    # that face (it moved a little since) is the same face, its other box is another one.
    tracked, earlier = (104, 102, 132, 132), (100, 100, 130, 130)
    assert lock.lockable([tracked], [earlier, SMALL]) == [tracked, SMALL]
    assert lock.lockable([], [earlier, SMALL]) == [earlier, SMALL]
    assert lock.lockable([tracked, SMALL], []) == [tracked, SMALL]


def test_a_click_window_is_a_square_of_three_fifths_of_the_shorter_side_inside_the_frame() -> None:
    assert RULE.click_search == 0.6
    for x, y, width, height, want in lock_sequences.CLICK_WINDOWS:
        got = lock.click_window(x, y, width, height, RULE.click_search)
        assert got == (None if want is None else tuple(want)), (x, y)


def test_a_click_near_no_box_searches_its_window_and_locks_what_is_found_near_it() -> None:
    windows: list[lock.Box] = []

    def search(found: list[lock.Box]) -> lock.Search:
        def run(window: lock.Box) -> list[lock.Box]:
            windows.append(window)
            return found

        return run

    tiny = (389, 68, 40, 40)
    target = lock.TargetLock(RULE)
    # Near a box: picked, no search.
    assert lock.lock_at(target, 405, 238, [LARGE, SMALL], search([]), 640, 480, 0.0) == "picked"
    assert target.box == SMALL and not target.fine and windows == []
    # Near none: the click's window is searched, and the box found at the click is locked.
    got = lock.lock_at(target, 409, 88, [LARGE, SMALL], search([SMALL, tiny]), 640, 480, 0.1)
    assert got == "searched" and windows == [(265, 0, 288, 288)]
    assert target.box == tiny and target.fine and target.state == "locked"
    query = target.query(0.2)
    assert query is not None and query.fine
    # A click on the same target keeps it followed at full resolution; another one does not.
    assert lock.lock_at(target, 409, 88, [tiny], None, 640, 480, 0.3) == "picked" and target.fine
    assert lock.lock_at(target, 470, 230, [SMALL], None, 640, 480, 0.4) == "picked"
    assert not target.fine
    # The search finds nothing near the click: released. So does a click with no search.
    assert lock.lock_at(target, 600, 400, [LARGE], search([SMALL]), 640, 480, 0.5) is None
    assert target.state == "none" and target.box is None
    target.hold(tiny, 0.6, fine=True)
    assert lock.lock_at(target, 600, 400, [LARGE], None, 640, 480, 0.7) is None
    assert target.state == "none" and not target.fine


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
    assert not target.lock(5, 5, [LARGE, SMALL], now=0.2)  # a click near no box releases
    assert target.state == "none"


def test_a_clicked_small_face_stays_the_target_beside_a_larger_one() -> None:
    events = [event for event, _ in lock_sequences.TWO_FACES]
    outcomes = lock_sequences.run(events, RULE)
    got = lock_sequences.decisions(events, outcomes)
    for i, ((event, want), have) in enumerate(zip(lock_sequences.TWO_FACES, got, strict=True)):
        assert have == want, (i, event)


def test_the_lock_holds_while_the_vehicle_searches_and_lets_go_when_its_search_ends() -> None:
    # The rule's numbers this sequence is written for (lock_sequences.THROUGH_SEARCH).
    assert (RULE.search_after_s, RULE.release_after_s, RULE.min_likeness) == (1.0, 3.0, 0.9)
    events = [event for event, _ in lock_sequences.THROUGH_SEARCH]
    got = lock_sequences.decisions(events, lock_sequences.run(events, RULE))
    for i, ((event, want), have) in enumerate(zip(lock_sequences.THROUGH_SEARCH, got, strict=True)):
        assert have == want, (i, event)
    # Without the vehicle's word the same snapshots release the walker at 3.5 s, and the walker
    # coming back at 5 s is not the target: only a click would lock it again.
    alone = lock_sequences.run(lock_sequences.WITHOUT_SEARCH, RULE)
    at = {
        event[1]: outcome
        for event, outcome in zip(lock_sequences.WITHOUT_SEARCH, alone, strict=True)
    }
    assert at[3.5][3] == "none"
    assert at[5.0][2:4] == [lock_sequences.BYSTANDER, "none"]


def test_only_a_turning_search_holds_the_lock() -> None:
    assert [lock.robot_searching(s) for s in ("left", "right", "timed_out", None)] == [
        True,
        True,
        False,
        False,
    ]


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


def face_op() -> spec.CascadeOperation:
    op = spec.load_spec(OPERATIONS_SPEC).op("face")
    assert isinstance(op, spec.CascadeOperation)
    return op


def test_the_smaller_face_stays_the_target_in_the_two_face_scene() -> None:
    op = face_op()
    video = TwoFaceVideo()
    relay = RelaySteps(op, RULE)
    scans: list[window.Scan] = []
    for i in range(0, 72, 2):  # 2.4 s of the scene's drift
        t = i / video.fps
        snap = relay.snapshot(cv2.cvtColor(video.render(i), cv2.COLOR_RGB2RGBA), t)
        scans.append(snap.scan)
        chosen = snap.chosen
        assert chosen is not None
        truth = video.small_centre(i) if i > 0 else video.face_centre(i)
        assert lock.contains(chosen, *truth), (i, chosen, truth)
        if snap.scan == "window":  # around the small face: the large one was not even searched
            assert snap.found.boxes == [chosen], (i, snap.found.boxes)
        if i == 0:  # the default choice was the large face: click the small one
            assert relay.click(*video.small_centre(0), t) == "picked"
    # From the click on, the window followed the small face on every snapshot but the tracker's
    # periodic full scans: it never lost it to a full scan.
    cadence = ["full"] + ["window"] * (op.params.full_scan_every - 1)
    assert scans == ["full", *(cadence * 2)[: len(scans) - 1]], scans


def test_a_face_too_small_for_the_reduced_scan_is_locked_by_a_click_and_followed() -> None:
    # The two-face scene's tiny face: the reduced scan (256 pixels wide) never finds it. A click
    # on it searches around the click at full resolution and locks it; from then on it is
    # followed at full resolution, through the tracker's periodic full scans too (which cannot
    # see it), and the goals stay on it.
    op = face_op()
    video = TwoFaceVideo()
    relay = RelaySteps(op, RULE)
    first = relay.snapshot(cv2.cvtColor(video.render(0), cv2.COLOR_RGB2RGBA), 0.0)
    tiny = video.tiny_centre(0)
    assert len(first.found.boxes) == 2
    assert lock.pick(*tiny, first.found.boxes, RULE.near) is None
    assert relay.click(*tiny, 0.01) == "searched"
    assert relay.lock.box is not None and lock.contains(relay.lock.box, *tiny)
    full_scans = []  # the snapshots after the click that scanned the whole frame
    for n in range(1, 34):  # one periodic full scan after the click's
        i = 2 * n
        snap = relay.snapshot(cv2.cvtColor(video.render(i), cv2.COLOR_RGB2RGBA), i / video.fps)
        if snap.full_scan:
            full_scans.append(n)
        tiny = video.tiny_centre(i)
        assert snap.scan == "window"
        assert snap.chosen is not None and lock.contains(snap.chosen, *tiny), (i, snap, tiny)
        assert snap.target is not None and lock.contains(snap.chosen, *snap.target)
        assert relay.lock.state == "locked" and relay.lock.fine
    # The first snapshot after the click and the tracker's periodic one (30 snapshots later)
    # were full scans, which did not find it; the window around where it was found it then, as
    # the tracker's window did on every snapshot between.
    assert full_scans == [1, 1 + op.params.full_scan_every]


def test_the_walker_looks_like_itself_near_and_far_and_unlike_the_bystander() -> None:
    # The arena's walker seen by the robot's camera from 0.8 to 4 m, and the bystander from two
    # places: each face as face_small finds it, its look as the relay's worker takes it. The
    # walker's looks are all at least min_likeness (0.9) alike; the bystander's, less.
    op = spec.load_spec(OPERATIONS_SPEC).op("face_small")
    renderer = Renderer(ARENA, Pinhole(hfov=CAMERA_HFOV))
    bystander_at = ARENA.billboard("bystander").pose
    assert bystander_at is not None

    def face_seen(robot: tuple[float, float], walker: tuple[float, float], at: Any) -> list[float]:
        yaw = math.atan2(at[1] - robot[1], at[0] - robot[0])
        state = RobotState(robot[0], robot[1], yaw, 0.0, 0.0)
        placed = tuple(
            Placed(b, Pose2D(*walker, facing(walker, robot)))
            if b.name == "walker"
            else Placed(b, b.placed(0.0, robot))
            for b in ARENA.billboards
        )
        rgba = cv2.cvtColor(renderer.render(Scene(0.0, state, placed, 0)), cv2.COLOR_RGB2RGBA)
        found = reference.detect(op, rgba).boxes
        # The face looked at is straight ahead: the box nearest the frame's middle column.
        ahead = min(found, key=lambda box: abs(box[0] + box[2] / 2 - rgba.shape[1] / 2))
        assert abs(ahead[0] + ahead[2] / 2 - rgba.shape[1] / 2) < ahead[2], (robot, at, found)
        return reference.look(rgba, ahead, RULE.look_bins)

    walker = [face_seen((1.0, 3.0), (1.0 + d, 3.0), (1.0 + d, 3.0)) for d in (0.8, 1.2, 2.0, 3.3)]
    bystander = [
        face_seen(robot, (7.5, 5.5), (bystander_at.x, bystander_at.y))
        for robot in ((1.0, 3.0), (2.0, 2.5))
    ]
    for a in walker:
        for b in walker:
            assert lock.likeness(a, b) >= RULE.min_likeness
        for b in bystander:
            assert lock.likeness(a, b) < RULE.min_likeness
