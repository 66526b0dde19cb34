"""``autopilot bench --foxglove``: do Foxglove viewers slow the vehicle?

One run, one agent (:class:`PilotedAgent`: the real :class:`~vehicle_agent.agent.Agent` logged in
to an in-process server, its synthetic camera's face answered by a goal per frame as a relay
would, its Foxglove server on a loopback port), in rounds of three phases: ``no viewer`` (the
Foxglove server up, nobody watching), ``viewer`` (a client in a process of its own, subscribed to
every channel and reading everything) and ``stuck viewer`` (a client subscribed to every channel
that never reads, so every image is encoded and every message queued for it). Each round runs
the phases in another order (rotated), so a drift of the shared machine's load falls on each
alike. Per phase and round, goal → Twist p50: from when the goal was due on the agent's loop to
when its Twist was published to the robot. The verdict compares each round's viewer phases with
that round's ``no viewer`` and takes the median over rounds. Target: within 10 %. Beside it, each
goal's handling, from when the loop began handling it to that publication: the vehicle's own
work, without the wait for the loop that the machine's load adds (the part that swings between
runs).

Beside it, per goal, how long the event log's listeners (the Foxglove view among them) took
with the goal's record: the time its Twist waited before the agent published a pilot step's
Twists ahead of its records (``Agent._act``), and now does not.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import statistics
import time
from collections.abc import AsyncIterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.robot import PRESETS, Robot
from app.tools.bench.foxglove_viewer import reading_viewer, stuck_viewer
from app.tools.bench.stats import summarize
from vehicle_agent import foxglove
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.events import EventLog
from vehicle_agent.foxglove import Address, FoxgloveLive
from vehicle_agent.robotlink import SimLink
from vehicle_agent.video import SyntheticVideo

# A goal comes this long after its frame, as from a relay on a quiet link.
GOAL_DELAY_S: Final = 0.03
BOX: Final = (40.0, 50.0)
NO_VIEWER, VIEWER, STUCK = "no viewer", "viewer", "stuck viewer"
PHASES: Final = (NO_VIEWER, VIEWER, STUCK)
ROUNDS: Final = 15
# With --quick: each phase measured in rounds this many times all the same.
QUICK_ROUNDS: Final = 2
# After a viewer comes or goes, before a phase is measured: the SDK's subscriptions settle.
SETTLE_S: Final = 0.2
MAX_P50_INCREASE_PCT: Final = 10.0


class _TimedLink(SimLink):
    """The in-process turtle, noting when the last Twist was published (the loop's clock)."""

    published_at = 0.0

    def publish(self, linear: float, angular: float) -> None:
        self.published_at = asyncio.get_running_loop().time()
        super().publish(linear, angular)


class PilotedAgent:
    """A real agent logged in to ``server_url``, a goal per camera frame with the face in it
    (:data:`GOAL_DELAY_S` later), its Foxglove server on a free loopback port. ``toggle_mode``:
    manual for 0.1 s every second too, so that the pilot's log has events."""

    def __init__(
        self,
        server_url: str,
        robot: Robot = PRESETS["diffdrive"],
        size: tuple[int, int] = (320, 240),
        fps: float = 15,
        toggle_mode: bool = False,
    ) -> None:
        self.events = EventLog()
        self.size = size
        self.goals: list[int] = []  # the seqs of the goals sent
        self.twists: set[int] = set()
        # The goals the pilot applied or dropped (manual mode): the ones the loop handled.
        self.handled: set[int] = set()
        # For each goal, from when it was due on the loop to its Twist's publication (ms).
        self.latencies_ms: list[float] = []
        # For each goal, from when the loop began handling it to its Twist's publication (ms):
        # the vehicle's own work, without the wait for the loop that the machine's load makes.
        self.handling_ms: list[float] = []
        self._handling: dict[int, float] = {}
        # For each goal applied, the listeners' time with its record (ms).
        self.goal_listeners_ms: list[float] = []
        self._goal_heard = 0.0
        self._due: dict[int, float] = {}
        self._toggle = toggle_mode
        self.video = SyntheticVideo(*size, fps=fps, on_frame=self._answer)
        self.link = _TimedLink()
        # The onboard law: the camera rides on the robot, so a goal left of centre turns it left.
        config = AgentConfig(server=server_url, robot=robot, profile="onboard", spawn_step=False)
        self.agent = Agent(config, self.video, self.link, self.events)
        self.live = FoxgloveLive(Address("127.0.0.1", 0), robot)
        self.events.listeners += [self._first, self.live.on_event, self._count]

    def _answer(self, sent: ev.FrameSent) -> None:
        self.events.emit(sent)
        if sent.face_x is None or sent.face_y is None:
            return
        width, height = self.size
        goal = channels.Goal(
            seq=sent.frame + 1, op="face", x=sent.face_x, y=sent.face_y, w=width, h=height,
            t=time.time() * 1000, frame=sent.frame, boxW=BOX[0], boxH=BOX[1],
        )  # fmt: skip
        loop = asyncio.get_running_loop()
        self._due[goal.seq] = loop.time() + GOAL_DELAY_S
        text = channels.dump(goal)
        loop.call_later(GOAL_DELAY_S, self._deliver, goal.seq, text)
        self.goals.append(goal.seq)

    def _deliver(self, seq: int, text: str) -> None:
        self._handling[seq] = asyncio.get_running_loop().time()
        self.agent.handle_channel_message(text, "relay")

    def _first(self, event: ev.AnyEvent) -> None:
        if isinstance(event, ev.GoalApplied):
            self._goal_heard = asyncio.get_running_loop().time()

    def _count(self, event: ev.AnyEvent) -> None:
        if isinstance(event, ev.TwistSent) and event.seq is not None:
            due, began = self._due.pop(event.seq, None), self._handling.pop(event.seq, None)
            if due is not None and began is not None:
                self.latencies_ms.append((self.link.published_at - due) * 1000)
                self.handling_ms.append((self.link.published_at - began) * 1000)
            self.twists.add(event.seq)
        if isinstance(event, ev.GoalApplied):
            since = asyncio.get_running_loop().time() - self._goal_heard
            self.goal_listeners_ms.append(since * 1000)
        if isinstance(event, ev.GoalApplied | ev.GoalDropped):
            self.handled.add(event.seq)

    async def _toggle_mode(self) -> None:
        manual = channels.dump(channels.ModeChange(mode="manual"))
        auto = channels.dump(channels.ModeChange(mode="auto"))
        while True:
            await asyncio.sleep(1.0)
            self.agent.handle_channel_message(manual, "relay")
            await asyncio.sleep(0.1)
            self.agent.handle_channel_message(auto, "relay")

    @contextlib.asynccontextmanager
    async def running(self) -> AsyncIterator[FoxgloveLive]:
        """The agent logged in and piloted, its Foxglove server up, until the block ends."""
        tasks = [
            asyncio.create_task(self.agent.run()),
            asyncio.create_task(self.live.stream_video(self.agent.camera_tap())),
        ]
        if self._toggle:
            tasks.append(asyncio.create_task(self._toggle_mode()))
        try:
            await asyncio.wait_for(self.agent.logged_in.wait(), 10)
            yield self.live
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            await foxglove.close(self.live)


def _median(values: list[float]) -> float | None:
    return round(statistics.median(values), 3) if values else None


async def run(server_url: str, seconds: float, fps: float, rounds: int = ROUNDS) -> dict[str, Any]:
    """Goal → Twist per phase over ``seconds`` in all (settling aside), and each viewer phase's
    change of p50 against the same round's ``no viewer`` (the median over rounds)."""
    piloted = PilotedAgent(server_url, size=(640, 480), fps=fps)
    phase_s = seconds / (rounds * len(PHASES))
    samples: dict[str, list[float]] = {phase: [] for phase in PHASES}
    # Per goal: the listeners' time with its record, and the loop's time from the goal to its
    # Twist (ms).
    handling: dict[str, list[float]] = {phase: [] for phase in PHASES}
    listeners: dict[str, list[float]] = {phase: [] for phase in PHASES}
    # Per round: each phase's p50 (ms; None without a sample), and the loop's CPU in the
    # Foxglove view (ms per s).
    round_p50: dict[str, list[float | None]] = {phase: [] for phase in PHASES}
    loop_ms_per_s: dict[str, list[float]] = {phase: [] for phase in PHASES}
    images = dict.fromkeys(PHASES, 0)
    channels_expected = 1 + len(foxglove.TYPED_CHANNELS) + len(foxglove.JSON_SCHEMAS)
    load_before = os.getloadavg()
    started = datetime.now(UTC)
    async with (
        piloted.running() as live,
        reading_viewer(live.url, channels_expected) as reader,
    ):
        await asyncio.sleep(1.0)  # the first goals and the limiter's ramp
        for index in range(rounds):
            shift = index % len(PHASES)
            for phase in PHASES[shift:] + PHASES[:shift]:
                async with contextlib.AsyncExitStack() as stack:
                    if phase == VIEWER:
                        await stack.enter_async_context(reader.watching())
                    elif phase == STUCK:
                        await stack.enter_async_context(stuck_viewer(live.url, channels_expected))
                    await asyncio.sleep(SETTLE_S)
                    piloted.latencies_ms.clear()
                    piloted.goal_listeners_ms.clear()
                    piloted.handling_ms.clear()
                    cpu_before, images_before = live.loop_cpu_s, live.images
                    await asyncio.sleep(phase_s)
                    found = list(piloted.latencies_ms)
                    samples[phase] += found
                    listeners[phase] += piloted.goal_listeners_ms
                    handling[phase] += piloted.handling_ms
                    round_p50[phase].append(statistics.median(found) if found else None)
                    loop_ms_per_s[phase].append((live.loop_cpu_s - cpu_before) * 1000 / phase_s)
                    images[phase] += live.images - images_before
    figures: dict[str, Any] = {
        "date": started.strftime("%Y-%m-%d %H:%M UTC"),
        "load": [round(v, 1) for v in (*load_before, *os.getloadavg())],
        "cores": os.cpu_count(),
        "seconds": seconds,
        "fps": fps,
        "rounds": rounds,
    }
    for phase in PHASES:
        pooled, work = summarize(samples[phase]), summarize(listeners[phase])
        measured = [v for v in round_p50[phase] if v is not None]
        figures[phase] = {
            "p50_rounds": [None if v is None else round(v, 3) for v in round_p50[phase]],
            "p50": _median(measured),
            "pooled": None if pooled is None else pooled.as_dict(),
            "listeners_p50": None if work is None else round(work.p50, 3),
            "handling_p50": _median(handling[phase]),
            "loop_ms_per_s": round(statistics.mean(loop_ms_per_s[phase]), 2),
            "images": images[phase],
        }
    for phase in (VIEWER, STUCK):
        pairs = zip(round_p50[NO_VIEWER], round_p50[phase], strict=True)
        changes = [
            (with_ / without - 1) * 100 for without, with_ in pairs if without and with_ is not None
        ]
        figures[phase]["p50_change_pct"] = _median(changes)
        handled, alone = figures[phase]["handling_p50"], figures[NO_VIEWER]["handling_p50"]
        if handled is not None and alone:
            figures[phase]["handling_change_pct"] = round((handled / alone - 1) * 100, 1)
    return figures


def write_report(out: Path, figures: dict[str, Any]) -> Path:
    """``foxglove.md`` (and ``foxglove.json``) in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "foxglove.json").write_text(json.dumps(figures, indent=2) + "\n")
    load = figures["load"]
    lines = [
        "# Foxglove viewers and the vehicle's loop",
        "",
        f"One agent (onboard profile, synthetic camera 640x480 at {figures['fps']:g} fps, a goal"
        f" per frame {GOAL_DELAY_S * 1000:.0f} ms after it), {figures['seconds']:g} s measured in"
        f" {figures['rounds']} rounds of three phases, each round in another order: the Foxglove"
        " server up with nobody watching, with a client in a process of its own reading every"
        " channel, and with a client subscribed to every channel that never reads.",
        f"Run {figures['date']} on {figures['cores']} cores; load average (1, 5, 15 min)"
        f" {load[0]}, {load[1]}, {load[2]} before and {load[3]}, {load[4]}, {load[5]} after.",
        "",
        "| phase | goal → Twist p50 (ms, median of rounds) | each round's p50 | change vs no"
        " viewer (median of rounds) | pooled p95 (ms) | samples | handling p50 (ms) | the"
        " listeners' time with a goal's record, p50 (ms) | the loop's CPU in the view (ms/s) |"
        " images encoded |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for phase in PHASES:
        found = figures[phase]
        pooled = found["pooled"]
        change = found.get("p50_change_pct")
        rounds = ", ".join("-" if v is None else f"{v:.2f}" for v in found["p50_rounds"])
        lines.append(
            f"| {phase} | {_ms(found['p50'])} | {rounds} |"
            f" {'' if change is None else f'{change:+.1f} %'} |"
            f" {_ms(None if pooled is None else pooled['p95'])} |"
            f" {0 if pooled is None else pooled['n']} | {_ms(found['handling_p50'], 3)} |"
            f" {_ms(found['listeners_p50'], 3)} |"
            f" {found['loop_ms_per_s']} | {found['images']} |"
        )
    verdicts = []
    for phase in (VIEWER, STUCK):
        change = figures[phase]["p50_change_pct"]
        if change is not None:
            within = "within" if change <= MAX_P50_INCREASE_PCT else "beyond"
            verdicts.append(f"{phase} {change:+.1f} % ({within} the {MAX_P50_INCREASE_PCT:g} %)")
    if verdicts:
        lines.append(f"\np50 against the same round's no viewer: {'; '.join(verdicts)}.")
    handling = [
        f"{phase} {figures[phase]['handling_change_pct']:+.1f} %"
        for phase in (VIEWER, STUCK)
        if "handling_change_pct" in figures[phase]
    ]
    if handling:
        lines.append(f"Handling p50 against no viewer's: {'; '.join(handling)}.")
    path = out / "foxglove.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _ms(value: float | None, digits: int = 2) -> str:
    return "not measured" if value is None else f"{value:.{digits}f}"
