"""``lock_held_pct``: the target lock in the two-face scene (docs/architecture.md, "Which target").

The stack runs under the default profile with the agent's ``two-faces`` video (a large face and
a smaller one, both drifting); once goals flow, the client page clicks the smaller face, as a
person would, and the run measures. The figure is the share of the goals the vehicle received
whose point lies on the smaller face (within half its size of its true centre, in the frame the
goal echoes), over the measured window; the default choice would put them all on the larger one.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.protocol.video import VIDEO_SIZE
from app.tools.bench.results import ProfileRun, Target
from app.tools.bench.stack import StackError, StackOptions, run_profile, wait_for
from vehicle_agent.video import TWO_FACES, TwoFaceVideo

if TYPE_CHECKING:
    from playwright.async_api import Browser, Page

log = logging.getLogger(__name__)

KEY = "lock_held_pct"
TARGET = Target(KEY, 95.0, False, "lock held on the smaller face >= 95 % of goals (two faces)")
LOCKED_TIMEOUT_S = 30.0
# The click lands where the smaller face was in the relay's latest frame; on a loaded machine the
# face can drift off that spot before the click reaches the relay (seen once: no lock in 30 s).
# A person would click again: so does the bench, when a click has not locked within this time.
CLICK_AGAIN_S = 5.0
_LOCKED_JS = "() => window.autopilotStatus.lock?.state === 'locked'"


def click_position(width: float, height: float, x: float, y: float) -> tuple[float, float]:
    """Where in a ``width`` × ``height`` video element (CSS pixels from its top left) frame pixel
    (x, y) of a VIDEO_SIZE frame is shown, letterboxed as object-fit: contain shows it."""
    w, h = VIDEO_SIZE
    scale = min(width / w, height / h)
    return (width - w * scale) / 2 + x * scale, (height - h * scale) / 2 + y * scale


async def run(
    browser: Browser, server_url: str, seconds: float, fps: float, workdir: Path
) -> tuple[ProfileRun, TwoFaceVideo]:
    """Run the stack on the two-face scene, lock on the smaller face, measure ``seconds``."""
    scene = TwoFaceVideo(*VIDEO_SIZE, fps)

    async def click_the_smaller_face(relay: Page, client: Page) -> None:
        # Where the smaller face is in the latest frame the relay analysed.
        frame = await relay.evaluate("() => window.autopilotStatus.lastGoal?.frame ?? null")
        if frame is None:
            raise StackError("the relay's goals carry no frame tag: cannot find the smaller face")
        video = client.get_by_test_id("video")
        box = await video.bounding_box()
        if box is None:
            raise StackError("the client's video is not on show")
        px, py = click_position(box["width"], box["height"], *scene.small_centre(int(frame)))
        await video.click(position={"x": px, "y": py})

    async def lock_the_smaller_face(relay: Page, client: Page) -> None:
        deadline = time.monotonic() + LOCKED_TIMEOUT_S
        clicks = 0
        while True:
            await click_the_smaller_face(relay, client)
            clicks += 1
            # Never 0: Playwright takes a timeout of 0 as none.
            wait_s = min(CLICK_AGAIN_S, max(0.1, deadline - time.monotonic()))
            try:
                await wait_for(client, _LOCKED_JS, wait_s, "no lock")
                break
            except StackError:
                if time.monotonic() >= deadline:
                    raise StackError(
                        f"{clicks} clicks on the smaller face did not lock it"
                        f" within {LOCKED_TIMEOUT_S:.0f} s"
                    ) from None
        log.info("the smaller face locked after %d click(s)", clicks)

    options = StackOptions("default", seconds, fps=fps, video=TWO_FACES, name="lock")
    try:
        measured = await run_profile(
            browser, server_url, options, workdir, prepare=lock_the_smaller_face
        )
    except StackError as exc:
        measured = ProfileRun("default", problems={KEY: str(exc)})
    return measured, scene


def figures(measured: ProfileRun, scene: TwoFaceVideo) -> dict[str, Any]:
    """``lock_held_pct`` and its counts, or the reason it is missing."""
    on_small = on_large = elsewhere = 0
    window = measured.window
    for t, frame in measured.goals:
        if window is None or not window[0] <= t <= window[1] or frame is None:
            continue
        point = measured.goal_points.get(frame)
        if point is None:
            continue
        if _on(point, scene.small_centre(frame), scene.small_px):
            on_small += 1
        elif _on(point, scene.face_centre(frame), scene.height // 4):
            on_large += 1
        else:
            elsewhere += 1
    total = on_small + on_large + elsewhere
    reason = measured.problems.get(KEY)
    if reason is None and total == 0:
        reason = "no tagged goal reached the vehicle while measuring"
    value = None if reason is not None else round(100.0 * on_small / total, 2)
    seconds = None if window is None else round(window[1] - window[0], 1)
    return {
        "value": value,
        "reason": reason,
        "details": {
            "goals": total,
            "on_smaller": on_small,
            "on_larger": on_large,
            "elsewhere": elsewhere,
            "seconds": seconds,
        },
    }


def merge(obj: dict[str, Any], measured: ProfileRun, scene: TwoFaceVideo) -> None:
    """Add the figure to the results object: at the top level, with its target, its counts
    under ``details.lock`` and the reason under ``unmeasured.lock`` when it is missing."""
    found = figures(measured, scene)
    obj[KEY] = found["value"]
    obj["targets"][KEY] = {"limit": TARGET.limit, "upper": TARGET.upper, "text": TARGET.text}
    obj["details"]["lock"] = found["details"]
    obj["unmeasured"]["lock"] = {} if found["reason"] is None else {KEY: found["reason"]}


def _on(point: tuple[float, float], centre: tuple[float, float], size: float) -> bool:
    return abs(point[0] - centre[0]) <= size / 2 and abs(point[1] - centre[1]) <= size / 2
