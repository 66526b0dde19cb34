"""``autopilot bench --onboard``: a robot that carries its camera follows the walker.

The real stack over the simulated arena (docs/simulated-arena.md): the server simulating the
diffdrive robot (``--robot diffdrive``: its camera rendered from its own pose and published on
its camera topic through the server's ``/rosbridge``), the relay page in headless Chromium, the
Python agent as it would run on a robot (``--robot diffdrive --profile onboard --video
ros:TOPIC --rosbridge`` the server's), and a client page that starts piloting and, once goals
flow, switches to :data:`OPERATION` and locks the target on the walker as a person would (the
walker is the largest face at the start; the lock keeps the bystander from taking over while the
walker is out of view). The lock lets a target go when it has been unseen for its release time;
then, as that person would, the client clicks the walker again once it is in view (each time is
in the report).

The truth: the robot's odometry as the agent received it (its event log's pose reports) and
where the walker stood at the same instant (the arena's time, read from ``GET /arena/state``
every :data:`ARENA_POLL_S`, and the walker's path): the walker's true bearing from the camera's
axis and its distance at each pose (``onboard_stats``). The figures:

- ``bearing_err_deg_p50`` / ``_p95``: the walker's bearing off the axis while in view, after
  the first acquisition;
- ``standoff_err_m_p50``: its distance less the standoff while in view (signed: positive too
  far), and ``standoff_abs_err_m_p50`` unsigned;
- ``reacquire_s``: the longest time from the walker leaving the view (it jogs past the robot's
  side to behind it once a round) to back within 5° of the axis; a departure not reacquired
  before the run ends leaves the figure missing, with the reason;
- ``goals_per_s``: the relay's goals over the window;
- ``snapshots_per_s`` and ``snapshot_ms_p50``: the frames the relay analysed, and each
  snapshot's time from taken to goal sent (what bounds the goals);
- ``frame_to_twist_ms_p50``: a camera frame's capture (its header stamp, on the agent's clock)
  to the first Twist the agent published from the goal the relay found in it;
- ``min_distance_m``: the walker's least distance from the robot's camera over the window;
- ``clicks_after_first``: how often the client had to click the walker again after the first
  lock (the lock had let it go).

The walk is the same for every operation: ``run`` measures one (:data:`OPERATIONS` are those
compared), each in an arena of its own whose walker starts its round afresh.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import httpx
from playwright.async_api import Error as PlaywrightError

from app.diffdrive.arena import ARENA, FACE_CENTRE_HEIGHT_M
from app.diffdrive.robot import CAMERA_HEIGHT_M
from app.protocol.control import PROFILES
from app.protocol.events import FrameSent, PoseReport, SearchEnded, SearchStarted, TwistSent
from app.protocol.robot import PRESETS
from app.protocol.video import VIDEO_SIZE
from app.recording import read_event_log
from app.tools.bench.lock import click_position
from app.tools.bench.onboard_stats import (
    ACQUIRED_DEG,
    bearing_errors_deg,
    min_distance_m,
    reacquisitions,
    sightings,
    standoff_errors_m,
)
from app.tools.bench.results import Target
from app.tools.bench.stack import StackError, StackOptions, run_profile, set_operation, wait_for
from app.tools.bench.stats import PoseSample, glass_to_command_ms, summarize

if TYPE_CHECKING:
    from playwright.async_api import Browser, Page

log = logging.getLogger(__name__)

PROFILE: Final = "onboard"
ROBOT: Final = PRESETS["diffdrive"]
# One round of the walker (28.9 s) and a little at --quick, three rounds at full length.
QUICK_S, FULL_S = 35.0, 90.0
# The operation that finds the walker wherever it goes in the arena: `face` finds a face up to
# about 2 m away, and the walker's round takes it 3 m from a robot that follows it
# (docs/simulated-arena.md); `face_small` finds it at 4 m. The DNN face operation is compared
# with it, when the relay offers it (``--ops`` chooses).
COMPARED: Final = ("face_small", "face_dnn")
ARENA_POLL_S: Final = 0.1
RELOCK_POLL_S: Final = 0.5
RELOCK_CLICK_TIMEOUT_S: Final = 2.0
LOCKED_TIMEOUT_S: Final = 30.0
CLICK_AGAIN_S: Final = 5.0
# The figures the run counts itself rather than reading the agent's event log.
RUN_KEYS: Final = ("goals_per_s", "clicks_after_first", "snapshots_per_s", "snapshot_ms_p50")
_LOCKED_JS = "() => window.autopilotStatus.lock?.state === 'locked'"

TARGETS: Final = (
    Target("bearing_err_deg_p50", 2.0, True, "bearing error p50 <= 2 deg"),
    Target("bearing_err_deg_p95", 10.0, True, "bearing error p95 <= 10 deg"),
    Target("standoff_err_m_p50", 0.10, True, "standoff error p50 within ±0.10 m"),
    Target("min_distance_m", 0.6, False, "never nearer the walker than 0.6 m"),
    Target("reacquire_s", 4.0, True, "reacquire <= 4 s"),
    Target("clicks_after_first", 0, True, "no click after the first lock"),
    Target("goals_per_s", 28.0, False, ">= 28 goals/s"),
)
FIGURE_KEYS: Final = (
    "bearing_err_deg_p50",
    "bearing_err_deg_p95",
    "standoff_err_m_p50",
    "standoff_abs_err_m_p50",
    "min_distance_m",
    "reacquire_s",
    "clicks_after_first",
    "goals_per_s",
    "snapshots_per_s",
    "snapshot_ms_p50",
    "frame_to_twist_ms_p50",
)


@dataclass
class ArenaClock:
    """The arena's time against this machine's monotonic clock, from ``GET /arena/state``."""

    readings: list[tuple[float, float]] = field(default_factory=list)

    def arena_time(self, t: float) -> float | None:
        """The arena's time at monotonic ``t``, between two readings (None outside them)."""
        pairs = zip(self.readings, self.readings[1:], strict=False)
        for (t0, r0), (t1, r1) in pairs:
            if t0 <= t <= t1:
                return r0 if t1 == t0 else r0 + (r1 - r0) * (t - t0) / (t1 - t0)
        return None

    def now(self) -> float | None:
        """The arena's time at the latest reading, None before any."""
        return self.readings[-1][1] if self.readings else None

    def walker(self) -> Callable[[float], tuple[float, float] | None]:
        """Where the walker stood at a monotonic time (None when the arena's time is unknown)."""
        walk = ARENA.billboard("walker").walk
        if walk is None:
            raise ValueError("the arena's walker does not walk")

        def at(t: float) -> tuple[float, float] | None:
            arena_t = self.arena_time(t)
            return None if arena_t is None else walk.at(arena_t)

        return at


async def poll_arena(server_url: str, room: str, clock: ArenaClock, stop: asyncio.Event) -> None:
    """Read the arena's time in ``room`` every :data:`ARENA_POLL_S` until ``stop``, each reading
    stamped at the middle of its request."""
    # Ten requests a second: httpx's log line for each would drown the run's.
    logging.getLogger("httpx").setLevel(logging.WARNING)
    async with httpx.AsyncClient(base_url=server_url, timeout=5.0) as client:
        while not stop.is_set():
            before = time.monotonic()
            answer = await client.get("/arena/state", params={"room": room})
            after = time.monotonic()
            answer.raise_for_status()
            clock.readings.append(((before + after) / 2, float(answer.json()["t"])))
            try:
                await asyncio.wait_for(stop.wait(), ARENA_POLL_S)
            except TimeoutError:
                pass


async def run(
    browser: Browser,
    server_url: str,
    seconds: float,
    fps: float,
    workdir: Path,
    operation: str,
    video: str | None = None,
) -> dict[str, Any]:
    """Run the stack over the arena for ``seconds`` with ``operation`` on the relay: the
    figures, the track the report plots, and the reason for each figure missing. ``video``: the
    agent's ``--video`` (default: the robot's camera topic)."""
    if ROBOT.camera is None:
        raise ValueError("the diffdrive robot has no camera")
    name = f"{PROFILE}-{operation}"
    room = f"bench-{name}"
    clock = ArenaClock()
    stop = asyncio.Event()
    pollers: list[asyncio.Task[None]] = []
    stop_relocking = asyncio.Event()
    relocker: list[asyncio.Task[None]] = []
    relocks: list[float] = []

    async def lock_the_walker(relay: Page, client: Page) -> None:
        pollers.append(asyncio.create_task(poll_arena(server_url, room, clock, stop)))
        await set_operation(relay, client, operation)
        await _lock_on_the_target(relay, client)
        relocker.append(asyncio.create_task(_keep_locked(client, clock, stop_relocking, relocks)))

    async def finish(relay: Page, client: Page) -> None:
        # While the client page is still open.
        stop_relocking.set()
        await asyncio.gather(*relocker)

    rosbridge = server_url.replace("http", "ws", 1) + f"/rosbridge?room={room}"
    options = StackOptions(
        PROFILE,
        seconds,
        fps=fps,
        video=video or f"ros:{ROBOT.camera.topic}",
        name=name,
        agent_args=("--robot", ROBOT.name, "--rosbridge", rosbridge),
    )
    found: dict[str, Any] = {"seconds": seconds, "fps": fps, "video": options.video}
    try:
        measured = await run_profile(
            browser, server_url, options, workdir, prepare=lock_the_walker, finish=finish
        )
    except StackError as exc:
        return found | {"problems": dict.fromkeys(FIGURE_KEYS, str(exc))}
    finally:
        stop.set()
        stop_relocking.set()
        await asyncio.gather(*pollers, *relocker, return_exceptions=True)
    window = measured.window
    if window is None:
        return found | {"problems": dict.fromkeys(FIGURE_KEYS, "nothing was measured")}
    span = window[1] - window[0]
    found["goals_per_s"] = round(measured.relay_goals / span, 2)
    # What bounds the goals: how many of the camera's frames the relay analysed, and how long
    # each snapshot took (taken -> goal sent).
    found["snapshots_per_s"] = round(measured.snapshots / span, 2)
    snapshot_ms = summarize([ms for t, ms in measured.processing if window[0] <= t <= window[1]])
    if snapshot_ms is not None:
        found["snapshot_ms_p50"] = round(snapshot_ms.p50, 1)
    found["relocks_s"] = [round(t - window[0], 2) for t in relocks if t >= window[0]]
    # Every click after the first lock, before the window or in it.
    found["clicks_after_first"] = len(relocks)
    events = workdir / f"events-{name}.jsonl"
    return found | figures(events, window, clock.walker(), math.radians(ROBOT.camera.hfov_deg))


async def _keep_locked(
    client: Page, clock: ArenaClock, stop: asyncio.Event, relocks: list[float]
) -> None:
    """As a person watching the client would: when the lock has let the walker go (unseen for
    longer than the lock's release time) and the walker is in view again, click it."""
    walk = ARENA.billboard("walker").walk
    assert walk is not None
    while not stop.is_set():
        try:
            await asyncio.wait_for(stop.wait(), RELOCK_POLL_S)
            return
        except TimeoutError:
            pass
        status = await client.evaluate(
            "() => ({ lock: window.autopilotStatus.lock?.state ?? 'none',"
            " pose: window.autopilotStatus.pose })"
        )
        arena_t = clock.now()
        if status["lock"] != "none" or status["pose"] is None or arena_t is None:
            continue
        pixel = walker_pixel(status["pose"], walk.at(arena_t))
        if pixel is None:
            continue
        video = client.get_by_test_id("video")
        box = await video.bounding_box()
        if box is None:
            continue
        px, py = click_position(box["width"], box["height"], *pixel)
        try:
            await video.click(position={"x": px, "y": py}, timeout=RELOCK_CLICK_TIMEOUT_S * 1000)
        except PlaywrightError as exc:  # the next poll tries again
            log.warning("could not click the walker: %s", exc.message.splitlines()[0])
            continue
        relocks.append(time.monotonic())
        log.info("the lock let the walker go: clicked it again")


def walker_pixel(pose: dict[str, float], place: tuple[float, float]) -> tuple[float, float] | None:
    """Where the walker's face is in the robot's camera frame, seen from ``pose`` ({x, y,
    theta}); None unless it is well inside the view."""
    if ROBOT.camera is None:
        return None
    dx, dy = place[0] - pose["x"], place[1] - pose["y"]
    bearing = math.atan2(dy, dx) - pose["theta"]
    bearing = math.atan2(math.sin(bearing), math.cos(bearing))
    half = math.radians(ROBOT.camera.hfov_deg) / 2
    if abs(bearing) > 0.8 * half:
        return None
    width, height = VIDEO_SIZE
    focal = (width / 2) / math.tan(half)
    ahead = math.hypot(dx, dy) * math.cos(bearing)
    up = FACE_CENTRE_HEIGHT_M - CAMERA_HEIGHT_M
    return width / 2 - focal * math.tan(bearing), height / 2 - focal * up / ahead


async def _lock_on_the_target(relay: Page, client: Page) -> None:
    """Click the relay's target (the walker: the largest face at the start) in the client's
    video until the lock holds, as a person would."""
    deadline = time.monotonic() + LOCKED_TIMEOUT_S
    clicks = 0
    while True:
        goal = await relay.evaluate("() => window.autopilotStatus.lastGoal")
        video = client.get_by_test_id("video")
        box = await video.bounding_box()
        if goal is None or box is None:
            raise StackError("no goal, or no video on the client, to click the walker on")
        px, py = click_position(box["width"], box["height"], goal["x"], goal["y"])
        await video.click(position={"x": px, "y": py})
        clicks += 1
        wait_s = min(CLICK_AGAIN_S, max(0.1, deadline - time.monotonic()))
        try:
            await wait_for(client, _LOCKED_JS, wait_s, "no lock")
        except StackError:
            if time.monotonic() >= deadline:
                raise StackError(
                    f"{clicks} clicks did not lock the walker within {LOCKED_TIMEOUT_S:.0f} s"
                ) from None
            continue
        log.info("the walker locked after %d click(s)", clicks)
        return


def figures(
    events: Path,
    window: tuple[float, float],
    walker: Callable[[float], tuple[float, float] | None],
    hfov: float,
) -> dict[str, Any]:
    """The figures from the agent's event log over ``window``, the walker's place by time."""
    problems: dict[str, str] = {}
    found: dict[str, Any] = {"problems": problems}
    if not events.exists():
        found["problems"] = dict.fromkeys(FIGURE_KEYS, "the agent wrote no event log")
        return found
    poses: list[PoseSample] = []
    frames: dict[int, float] = {}
    commands: list[tuple[float, int]] = []
    searches: list[tuple[float, str]] = []
    start, end = window
    for event in read_event_log(events):
        match event:
            case PoseReport(x=x, y=y, theta=theta, t=t) if start <= t <= end:
                poses.append(PoseSample(t, x, y, theta))
            case FrameSent(frame=frame, t=t):
                frames[frame] = t
            case TwistSent(frame=int(frame), t=t):
                commands.append((t, frame))
            case SearchStarted(side=side, t=t) if start <= t <= end:
                searches.append((t - start, f"searching {side}"))
            case SearchEnded(why=why, t=t) if start <= t <= end:
                searches.append((t - start, f"search {why}"))
    track = sightings(poses, walker)
    bearing = summarize(bearing_errors_deg(track, hfov))
    if bearing is None:
        problems["bearing_err_deg_p50"] = f"the robot never had the walker within {ACQUIRED_DEG:g}°"
    else:
        found["bearing_err_deg_p50"] = round(bearing.p50, 2)
        found["bearing_err_deg_p95"] = round(bearing.p95, 2)
    nearest = min_distance_m(track)
    if nearest is not None:
        found["min_distance_m"] = round(nearest, 3)
    errors = standoff_errors_m(track, hfov, PROFILES[PROFILE].standoff_m)
    signed, unsigned = summarize(errors), summarize([abs(e) for e in errors])
    if signed is not None and unsigned is not None:
        found["standoff_err_m_p50"] = round(signed.p50, 3)
        found["standoff_abs_err_m_p50"] = round(unsigned.p50, 3)
    back = reacquisitions(track, hfov)
    longest = max((r.after_s for r in back if r.after_s is not None), default=None)
    # A departure the run ended on lasted at least until the end: it changes the longest only
    # when it had already lasted longer.
    missed = [
        r for r in back if r.after_s is None and (longest is None or end - r.left_at > longest)
    ]
    if not back:
        problems["reacquire_s"] = "the walker never left the view while measuring"
    elif missed:
        problems["reacquire_s"] = (
            f"the walker left the view by the {missed[0].side} at"
            f" {missed[0].left_at - start:.1f} s and was not back within {ACQUIRED_DEG:g}°"
            f" in the {end - missed[0].left_at:.1f} s before the run ended"
        )
    else:
        found["reacquire_s"] = round(longest or 0.0, 2)
    latency = summarize(glass_to_command_ms(frames, commands))
    if latency is None:
        problems["frame_to_twist_ms_p50"] = "no Twist named a frame the camera tagged"
    else:
        found["frame_to_twist_ms_p50"] = round(latency.p50, 1)
    found["reacquisitions"] = [
        {"left_at_s": round(r.left_at - start, 2), "side": r.side, "after_s": r.after_s}
        for r in back
    ]
    found["searches"] = [[round(t, 2), what] for t, what in searches]
    found["track"] = [
        [round(s.t - start, 3), round(math.degrees(s.bearing), 2), round(s.distance, 3)]
        for s in track
    ]
    found["samples"] = {"poses": len(track), "frames": len(frames), "twists": len(commands)}
    for key in FIGURE_KEYS:
        if key not in found and key not in problems and key not in RUN_KEYS:
            problems[key] = "no sighting of the walker in view after the first acquisition"
    return found


def write_report(out: Path, runs: dict[str, dict[str, Any]], run_info: dict[str, Any]) -> Path:
    """``onboard.json``, ``onboard.md`` and each operation's track plot in ``out``, from
    ``runs`` (each operation's :func:`run`, in the order measured); the report's path."""
    out.mkdir(parents=True, exist_ok=True)
    obj = {
        "run": run_info,
        "operations": {
            op: {k: v for k, v in found.items() if k != "track"} for op, found in runs.items()
        },
    }
    (out / "onboard.json").write_text(json.dumps(obj, indent=2, allow_nan=False) + "\n")
    first = next(iter(runs.values()))
    ops = list(runs)
    lines = [
        "# Onboard following: the robot that carries its camera, after the walker",
        "",
        f"`{run_info['command']}` on {run_info['machine']}, {run_info['started']}"
        f" (load average {run_info['load_average'][0]} → {run_info['load_average'][1]}):"
        f" {first['seconds']:g} s measured for each operation, one after the other, the camera"
        f" at {first['fps']:g} frames/s (`--video {first['video']}`).",
        "",
        "| figure | " + " | ".join(f"`{op}`" for op in ops) + " | target |",
        "|---|" + "---|" * len(ops) + "---|",
    ]
    targets = {t.key: t for t in TARGETS}
    for key in FIGURE_KEYS:
        target = targets.get(key)
        shown = [_shown(found.get(key), key, target) for found in runs.values()]
        text = "" if target is None else target.text
        lines.append(f"| `{key}` | " + " | ".join(shown) + f" | {text} |")
    for op, found in runs.items():
        lines += ["", f"## `{op}`"]
        lines += _details(found, f"onboard-track-{op}.png", out)
    path = out / "onboard.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _shown(value: float | None, key: str, target: Target | None) -> str:
    """A figure as the report's table shows it, with whether it meets its target."""
    if value is None:
        return "not measured"
    if target is None:
        return f"{value:g}"
    met = target.met(abs(value) if key == "standoff_err_m_p50" else value)
    return f"{value:g} {'✓' if met else '✗'}"


def _details(found: dict[str, Any], plot_name: str, out: Path) -> list[str]:
    """One operation's part of the report: what was not measured, the departures, the clicks,
    and its plot (written to ``out``)."""
    lines: list[str] = []
    problems = found.get("problems", {})
    if problems:
        lines += ["", "Not measured:", ""]
        lines += [f"- `{key}`: {why}" for key, why in problems.items()]
    back = found.get("reacquisitions", [])
    if back:
        lines += ["", "The walker out of view and back within 5° (s into the run):", ""]
        for r in back:
            after = "not back" if r["after_s"] is None else f"back after {r['after_s']:.2f} s"
            lines.append(f"- left by the {r['side']} at {r['left_at_s']:.1f} s, {after}")
    relocks = found.get("relocks_s", [])
    lines += [
        "",
        "The lock let the walker go and the client clicked it again: "
        + (", ".join(f"{t:.1f} s" for t in relocks) if relocks else "never")
        + ".",
    ]
    if _plot(out / plot_name, found):
        lines += ["", f"![bearing and distance]({plot_name})"]
    return lines


def _plot(path: Path, found: dict[str, Any]) -> bool:
    """The walker's bearing and distance over the run, the view's edges, the standoff and the
    searches; False when there is nothing to plot or no matplotlib."""
    track = found.get("track") or []
    if not track:
        return False
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log.warning("matplotlib missing: no onboard plot")
        return False
    t = [row[0] for row in track]
    half = (ROBOT.camera.hfov_deg if ROBOT.camera else 0.0) / 2
    fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(9, 6))
    top.plot(t, [row[1] for row in track], ".", ms=2, label="walker's bearing")
    for edge in (-half, half):
        top.axhline(edge, color="grey", ls="--", lw=0.8)
    top.axhspan(-ACQUIRED_DEG, ACQUIRED_DEG, color="green", alpha=0.15, label="±5°")
    for at, what in found.get("searches", []):
        top.axvline(at, color="red" if what.startswith("searching") else "orange", lw=0.8)
    top.set_ylabel("bearing (deg, + left)")
    top.set_ylim(-180, 180)
    top.legend(loc="upper right", fontsize=8)
    bottom.plot(t, [row[2] for row in track], lw=1, label="distance")
    bottom.axhline(PROFILES[PROFILE].standoff_m, color="grey", ls="--", lw=0.8, label="standoff")
    bottom.set_ylabel("distance (m)")
    bottom.set_xlabel("s into the run (red: a search began, orange: it ended)")
    bottom.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return True
