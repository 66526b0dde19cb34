"""Run the real stack under one profile and collect its samples.

Server (already running), a headless relay page, the Python vehicle agent with the synthetic
video as a subprocess writing its JSON-lines event log, and a headless client page that presses
Start Piloting. The relay's numbers come from its read-only ``window.autopilotStatus``; the
vehicle's from its event log. Agent events and this process share one clock
(``time.monotonic()``, CLOCK_MONOTONIC is system-wide), so windows set here cut the agent's log.
"""

from __future__ import annotations

import asyncio
import json
import logging
import signal
import sys
import time
from collections.abc import Awaitable, Callable
from contextlib import AsyncExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from playwright.async_api import Browser, ConsoleMessage, Page
from playwright.async_api import Error as PlaywrightError
from playwright.async_api import TimeoutError as PlaywrightTimeout

from app.protocol.control import PROFILES
from app.protocol.events import FrameSent, GoalApplied, PoseReport, TwistSent
from app.protocol.opencv import OpenCvBuild
from app.protocol.urls import page_url
from app.protocol.video import VIDEO_FPS, VIDEO_SIZE
from app.recording import read_event_log
from app.tools.bench.cpu import tree_cpu_s
from app.tools.bench.results import MemorySample, ProfileRun
from app.tools.bench.stats import (
    FaceSample,
    PoseSample,
    TruthSample,
    heading_track,
    standoff_errors,
)
from vehicle_agent.core.control import pixel_to_terrain

log = logging.getLogger(__name__)

# Generous: a loaded 2-core machine compiles the 11 MB OpenCV.js slowly.
ANALYZER_TIMEOUT_S = 180.0
CONNECT_TIMEOUT_S = 120.0
FIRST_GOAL_TIMEOUT_S = 90.0
# A switched operation's first goal (the DNN's first full scan is seconds on a loaded machine).
SWITCH_TIMEOUT_S = 30.0
AGENT_EXIT_TIMEOUT_S = 15.0
SETTLE_S = 1.0
POLL_S = 2.0
# Memory is first sampled this long after goals start (caches and JIT code settle first).
MEMORY_FIRST_SAMPLE_S = 5.0
# Growth is measured from the first sample after this share of the run (at most 2 minutes): the
# relay's bounded buffers (its latest 2000 processing samples, about 100 s at 20 snapshots/s)
# fill up first, and filling a bounded buffer is not a leak. Every sample stays in the plot.
MEMORY_BASELINE_SHARE = 0.2
MEMORY_BASELINE_MAX_S = 120.0

# New processing samples since the last poll (the relay keeps a bounded ring of them).
_POLL_JS = """(seen) => {
  const s = window.autopilotStatus;
  const k = Math.min(s.snapshots - seen, s.processingMs.length);
  const ms = k > 0 ? s.processingMs.slice(-k) : [];
  return { snapshots: s.snapshots, goalsSent: s.goalsSent, ms };
}"""

# The client's glass-to-glass samples since the last poll (its health keeps a bounded ring).
_CLIENT_POLL_JS = """(seen) => {
  const h = window.autopilotHealth;
  const k = Math.min(h.framesTimed - seen, h.glassToGlassMs.length);
  return { framesTimed: h.framesTimed, ms: k > 0 ? h.glassToGlassMs.slice(-k) : [] };
}"""

# JS heap after a full collection when the browser exposes gc (--js-flags=--expose-gc), so that
# garbage not yet collected is not mistaken for growth.
_JS_HEAP_JS = """() => {
  if (typeof window.gc === 'function') window.gc();
  return performance.memory ? performance.memory.usedJSHeapSize : null;
}"""

# The relay page's declared window.autopilotMemory() (docs/contracts.md): its analyzer's OpenCV
# WASM heap size.
_WASM_HEAP_JS = "async () => (await window.autopilotMemory())?.wasmHeapBytes ?? null"


@dataclass(frozen=True)
class StackOptions:
    """How long and how to run one profile."""

    profile: str
    duration_s: float
    size: tuple[int, int] = VIDEO_SIZE
    fps: float = VIDEO_FPS
    memory_every_s: float = 10.0
    sweep_s: float | None = None  # the synthetic face's cycle; None: the agent's default
    # The agent's --video, and a name for the run (room and file names) when not the profile's.
    video: str = "synthetic"
    name: str | None = None
    # More options for the agent (the flight recorder's, say).
    agent_args: tuple[str, ...] = ()
    # The OpenCV.js build the relay page loads (its ?opencv=); None: the one it loads unless told.
    opencv: OpenCvBuild | None = None


class StackError(RuntimeError):
    """The stack did not come up far enough to measure; the message says which step failed."""


async def run_profile(
    browser: Browser,
    server_url: str,
    options: StackOptions,
    workdir: Path,
    prepare: Callable[[Page, Page], Awaitable[None]] | None = None,
    client_browser: Browser | None = None,
    finish: Callable[[Page, Page], Awaitable[None]] | None = None,
    relay_init_script: str | None = None,
) -> ProfileRun:
    """Bring the stack up under ``options.profile``, pilot for ``duration_s``, take it down.

    ``prepare(relay, client)``, when given, runs once goals flow, before the measurement.
    ``client_browser``, when given, holds the client page, so that ``browser``'s processes
    are the relay's alone. ``finish(relay, client)``, when given, runs right after the
    measurement, while the pages still pilot. ``relay_init_script`` runs in the relay page
    before its own scripts (a benchmark's probe).
    """
    run = ProfileRun(options.profile)
    name = options.name or options.profile
    room = f"bench-{name}"
    events_path = workdir / f"events-{name}.jsonl"
    agent_log = workdir / f"agent-{name}.log"
    async with AsyncExitStack() as stack:
        relay = await _open_page(stack, browser, "relay", relay_init_script)
        # Unattended, as `autopilot relay` opens it: no preview for nobody to watch.
        query: dict[str, str | int] = {"name": "relay", "auto": 1, "profile": options.profile}
        if options.opencv is not None:
            query["opencv"] = options.opencv
        await relay.goto(page_url(server_url, "relay", room, **query, preview=0))
        await wait_for(
            relay,
            "() => window.autopilotStatus?.analyzerReady === true",
            ANALYZER_TIMEOUT_S,
            "the relay's OpenCV.js analyzer did not become ready",
        )
        agent = await _start_agent(server_url, room, options, events_path, agent_log)
        stack.push_async_callback(_stop_agent, agent, agent_log)
        client = await _open_page(stack, client_browser or browser, "client")
        await client.goto(page_url(server_url, "client", room, name="client", auto=1))
        start = client.get_by_role("button", name="Start Piloting")
        await _unless_agent_exits(
            agent,
            agent_log,
            _step(
                start.click(timeout=CONNECT_TIMEOUT_S * 1000),
                "the client never reached the relay (Start Piloting stayed disabled)",
            ),
        )
        await _unless_agent_exits(
            agent,
            agent_log,
            wait_for(
                relay,
                "() => window.autopilotStatus.goalsSent > 0",
                FIRST_GOAL_TIMEOUT_S,
                "piloting started but the relay sent no goal",
            ),
        )
        if prepare is not None:
            await prepare(relay, client)
        log.info("%s run: goals flowing, measuring for %.0f s", name, options.duration_s)
        cpu_before = tree_cpu_s({"agent": [agent.pid]})
        run.window = await _measure(relay, client, options, run)
        used = tree_cpu_s({"agent": [agent.pid]})["agent"] - cpu_before["agent"]
        run.agent_cores = used / (run.window[1] - run.window[0])
        if finish is not None:
            await finish(relay, client)
        await client.get_by_role("button", name="Stop Piloting").click()
    _read_events(run, events_path, options)
    return run


async def _measure(
    relay: Page, client: Page, options: StackOptions, run: ProfileRun
) -> tuple[float, float]:
    """Poll the relay's samples and memory, and the client's glass to glass, for
    ``duration_s``; returns the window measured."""
    begin = time.monotonic()
    first = await relay.evaluate(_POLL_JS, 0)
    seen = first["snapshots"]
    timed = (await client.evaluate(_CLIENT_POLL_JS, 0))["framesTimed"]
    next_memory = begin + MEMORY_FIRST_SAMPLE_S
    run.memory_baseline_at = begin + max(
        MEMORY_FIRST_SAMPLE_S,
        min(MEMORY_BASELINE_MAX_S, MEMORY_BASELINE_SHARE * options.duration_s),
    )
    while (now := time.monotonic()) < begin + options.duration_s:
        if now >= next_memory:
            run.memory.append(await _memory(relay, run))
            next_memory += options.memory_every_s
        await asyncio.sleep(POLL_S)
        seen = (await _collect(relay, seen, run))["snapshots"]
        timed = await _collect_client(client, timed, run)
    last = await _collect(relay, seen, run)
    await _collect_client(client, timed, run)
    run.snapshots = last["snapshots"] - first["snapshots"]
    run.relay_goals = last["goalsSent"] - first["goalsSent"]
    run.memory.append(await _memory(relay, run))
    return begin, time.monotonic()


async def _step(action: Awaitable[Any], failure: str) -> None:
    try:
        await action
    except PlaywrightTimeout as exc:
        raise StackError(failure) from exc


async def _unless_agent_exits(
    agent: asyncio.subprocess.Process, log_path: Path, step: Awaitable[None]
) -> None:
    """Run ``step``, failing at once with the agent's last words if the agent dies meanwhile."""
    step_task = asyncio.ensure_future(step)
    exit_task = asyncio.ensure_future(agent.wait())
    await asyncio.wait({step_task, exit_task}, return_when=asyncio.FIRST_COMPLETED)
    if step_task.done():
        exit_task.cancel()
        step_task.result()
        return
    step_task.cancel()
    await asyncio.gather(step_task, return_exceptions=True)
    tail = " | ".join(log_path.read_text(errors="replace").splitlines()[-5:])
    raise StackError(f"the vehicle agent exited with status {agent.returncode}: {tail}")


async def _open_page(
    stack: AsyncExitStack, browser: Browser, role: str, init_script: str | None = None
) -> Page:
    context = await browser.new_context()
    stack.push_async_callback(context.close)
    if init_script is not None:
        await context.add_init_script(init_script)
    page = await context.new_page()

    def on_console(message: ConsoleMessage) -> None:
        if message.type == "error":
            log.warning("%s page: %s", role, message.text)

    page.on("console", on_console)
    page.on("pageerror", lambda error: log.error("%s page error: %s", role, error))
    return page


async def set_operation(relay: Page, client: Page, operation: str) -> None:
    """Switch the relay to ``operation`` from the client, as a person would, and wait for its
    goals."""
    await client.get_by_test_id("operation").select_option(operation)
    await client.get_by_role("button", name="Set Operation").click()
    await wait_for(
        relay,
        f"() => window.autopilotStatus.lastGoal?.op === {json.dumps(operation)}",
        SWITCH_TIMEOUT_S,
        f"no goal from {operation} after Set Operation",
    )


async def wait_for(page: Page, condition: str, timeout_s: float, failure: str) -> None:
    """Wait until the JS function ``condition`` holds on ``page``, else StackError(failure)."""
    # ``condition`` is a JS function: under the pages' CSP (no 'unsafe-eval') Playwright cannot
    # evaluate a bare expression.
    try:
        await page.wait_for_function(condition, timeout=timeout_s * 1000, polling=250)
    except PlaywrightTimeout as exc:
        raise StackError(f"{failure} within {timeout_s:.0f} s") from exc


async def _start_agent(
    server_url: str, room: str, options: StackOptions, events: Path, log_path: Path
) -> asyncio.subprocess.Process:
    command = [
        sys.executable, "-m", "vehicle_agent",
        "--server", server_url, "--room", room, "--name", "vehicle",
        "--video", options.video, "--size", "{}x{}".format(*options.size),
        "--fps", f"{options.fps:g}", "--profile", options.profile, "--events", str(events),
    ]  # fmt: skip
    if options.sweep_s is not None:
        command += ["--sweep-s", f"{options.sweep_s:g}"]
    command += options.agent_args
    log.debug("starting the agent: %s", " ".join(command))
    with log_path.open("wb") as out:
        return await asyncio.create_subprocess_exec(
            *command, stdin=asyncio.subprocess.DEVNULL, stdout=out, stderr=out
        )


async def _stop_agent(agent: asyncio.subprocess.Process, log_path: Path) -> None:
    if agent.returncode is None:
        agent.send_signal(signal.SIGTERM)
        try:
            await asyncio.wait_for(agent.wait(), AGENT_EXIT_TIMEOUT_S)
        except TimeoutError:
            log.warning("the agent ignored SIGTERM for %.0f s: killing it", AGENT_EXIT_TIMEOUT_S)
            agent.kill()
            await agent.wait()
    # The agent exits 0 on SIGTERM; anything else means it failed on its own.
    if agent.returncode not in (0, -signal.SIGTERM):
        tail = log_path.read_text(errors="replace").splitlines()[-15:]
        log.error(
            "the agent exited with %s; its last lines:\n%s", agent.returncode, "\n".join(tail)
        )


async def _collect(relay: Page, seen: int, run: ProfileRun) -> dict[str, Any]:
    """Append the processing samples taken since snapshot ``seen``; returns the relay's counters."""
    polled: dict[str, Any] = await relay.evaluate(_POLL_JS, seen)
    now = time.monotonic()
    run.processing.extend((now, float(ms)) for ms in polled["ms"])
    return polled


async def _collect_client(client: Page, timed: int, run: ProfileRun) -> int:
    """Append the client's glass-to-glass samples since frame ``timed``; returns its count."""
    polled: dict[str, Any] = await client.evaluate(_CLIENT_POLL_JS, timed)
    run.client_glass.extend(float(ms) for ms in polled["ms"])
    count: int = polled["framesTimed"]
    return count


async def _memory(relay: Page, run: ProfileRun) -> MemorySample:
    js_heap = await relay.evaluate(_JS_HEAP_JS)
    if js_heap is None:
        run.problems.setdefault(
            "memory_growth_pct",
            "performance.memory is missing (needs --enable-precise-memory-info)",
        )
    wasm_heap = None
    try:
        wasm_heap = await relay.evaluate(_WASM_HEAP_JS)
    except PlaywrightError as exc:
        # Say so in the report rather than stop the run.
        run.problems.setdefault("memory_growth_pct", f"cannot read the WASM heap: {exc}")
    if wasm_heap is None:
        run.problems.setdefault("memory_growth_pct", "the relay has no analyzer to measure")
    return MemorySample(
        time.monotonic(),
        float(js_heap) if js_heap is not None else None,
        float(wasm_heap) if wasm_heap is not None else None,
    )


def _read_events(run: ProfileRun, path: Path, options: StackOptions) -> None:
    """Fill ``run`` from the agent's event log (the kinds of ``app/protocol/events.py``)."""
    if not path.exists():
        run.problems["glass_to_command_ms_p50"] = "the agent wrote no event log"
        return
    run.frame_size = options.size
    poses: list[PoseSample] = []
    truth: list[TruthSample] = []
    first_command: float | None = None
    for event in read_event_log(path):
        match event:
            case FrameSent(frame=frame, face_x=face_x, face_y=face_y, jump=jump, t=t):
                run.frame_sent[frame] = t
                if face_x is not None and face_y is not None:  # a scene that knows its face
                    run.face.append(FaceSample(frame, face_x, face_y, jump))
                    truth.append(TruthSample(t, face_x, face_y, *options.size))
            case GoalApplied(frame=frame, x=x, y=y, t=t):
                run.goals.append((t, frame))
                if frame is not None:
                    run.goal_points.setdefault(frame, (x, y))
            case TwistSent(frame=int(frame), t=t):
                run.commands.append((t, frame))
                first_command = t if first_command is None else first_command
            case PoseReport(x=x, y=y, theta=theta, t=t):
                poses.append(PoseSample(t, x, y, theta))
    window = run.window or (float("-inf"), float("inf"))
    poses = [p for p in poses if window[0] <= p.t <= window[1]]
    run.heading = heading_track(poses, truth, pixel_to_terrain)
    if PROFILES[options.profile].law == "follow":
        standoff = PROFILES[options.profile].standoff_m
        run.position_error = standoff_errors(poses, truth, pixel_to_terrain, standoff)
    if first_command is not None:
        run.settle_at = max(first_command, window[0]) + SETTLE_S
