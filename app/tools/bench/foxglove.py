"""``autopilot bench --foxglove``: does a Foxglove viewer that never reads slow the vehicle?

One run, one agent (:class:`PilotedAgent`: the real :class:`~vehicle_agent.agent.Agent` logged in
to an in-process server, its synthetic camera's face answered by a goal per frame as a relay
would, its Foxglove server on a loopback port), in alternating phases: ``plain`` (the Foxglove
server up, nobody watching) and ``stuck viewer`` (a client subscribed to every channel that
never reads, so every image is encoded and every message queued for it). Per phase, goal →
Twist: from when the goal was due on the agent's loop to the Twist it caused, which is what a
loop slowed by the viewer would lengthen. Target: the stuck phases' p50 within 10 % of the plain
ones'.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import statistics
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any, Final

from websockets.asyncio.client import connect

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.robot import PRESETS, Robot
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
PHASES: Final = ("plain", "stuck viewer")
ROUNDS: Final = 6
MAX_P50_INCREASE_PCT: Final = 10.0
# The subprotocols a Foxglove client offers the SDK's server.
SUBPROTOCOLS: Final[Any] = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


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
        # Goal → Twist (ms) for each goal, from when it was due on the loop.
        self.latencies_ms: list[float] = []
        self._due: dict[int, float] = {}
        self._toggle = toggle_mode
        self.video = SyntheticVideo(*size, fps=fps, on_frame=self._answer)
        # The onboard law: the camera rides on the robot, so a goal left of centre turns it left.
        config = AgentConfig(server=server_url, robot=robot, profile="onboard", spawn_step=False)
        self.agent = Agent(config, self.video, SimLink(), self.events)
        self.live = FoxgloveLive(Address("127.0.0.1", 0), robot)
        self.events.listeners += [self.live.on_event, self._count]

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
        loop.call_later(GOAL_DELAY_S, self.agent.handle_channel_message, text, "relay")
        self.goals.append(goal.seq)

    def _count(self, event: ev.AnyEvent) -> None:
        if isinstance(event, ev.TwistSent) and event.seq is not None:
            due = self._due.pop(event.seq, None)
            if due is not None:
                self.latencies_ms.append((asyncio.get_running_loop().time() - due) * 1000)
            self.twists.add(event.seq)
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


@contextlib.asynccontextmanager
async def stuck_viewer(url: str, channels_expected: int) -> AsyncIterator[None]:
    """A Foxglove client subscribed to every channel that reads nothing more (its library reads
    a frame ahead, then leaves the socket unread)."""
    # Closing: the server answers the close frame after what it queued, which is never read.
    async with connect(url, subprotocols=SUBPROTOCOLS, max_queue=1, close_timeout=0.5) as ws:
        ids: list[int] = []
        async with asyncio.timeout(5):
            while len(ids) < channels_expected:
                message = json.loads(await ws.recv())
                if message.get("op") == "advertise":
                    ids += [channel["id"] for channel in message["channels"]]
        subscribe = [{"id": i, "channelId": c} for i, c in enumerate(ids)]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": subscribe}))
        yield


async def run(server_url: str, seconds: float, fps: float) -> dict[str, Any]:
    """Goal → Twist per phase over ``seconds`` in all, and the stuck viewer's increase of p50."""
    piloted = PilotedAgent(server_url, size=(640, 480), fps=fps)
    phase_s = seconds / (ROUNDS * len(PHASES))
    samples: dict[str, list[float]] = {phase: [] for phase in PHASES}
    # The loop's CPU in the Foxglove view, ms per second of each phase.
    loop_ms_per_s: dict[str, list[float]] = {phase: [] for phase in PHASES}
    channels_expected = 1 + len(foxglove.TYPED_CHANNELS) + len(foxglove.JSON_SCHEMAS)
    async with piloted.running() as live:
        await asyncio.sleep(1.0)  # the first goals and the limiter's ramp
        for _ in range(ROUNDS):
            for phase in PHASES:
                async with contextlib.AsyncExitStack() as stack:
                    if phase == "stuck viewer":
                        await stack.enter_async_context(stuck_viewer(live.url, channels_expected))
                    piloted.latencies_ms.clear()
                    cpu_before = live.loop_cpu_s
                    await asyncio.sleep(phase_s)
                    samples[phase] += piloted.latencies_ms
                    loop_ms_per_s[phase].append((live.loop_cpu_s - cpu_before) * 1000 / phase_s)
        images = live.images
    figures: dict[str, Any] = {"seconds": seconds, "fps": fps, "rounds": ROUNDS, "images": images}
    for phase, values in samples.items():
        found = summarize(values)
        figures[phase] = None if found is None else found.as_dict()
        figures[f"{phase} loop_ms_per_s"] = round(statistics.mean(loop_ms_per_s[phase]), 2)
    plain, stuck = figures["plain"], figures["stuck viewer"]
    if plain is not None and stuck is not None:
        figures["p50_increase_pct"] = round((stuck["p50"] / plain["p50"] - 1) * 100, 1)
    return figures


def write_report(out: Path, figures: dict[str, Any]) -> Path:
    """``foxglove.md`` (and ``foxglove.json``) in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "foxglove.json").write_text(json.dumps(figures, indent=2) + "\n")
    lines = [
        "# A Foxglove viewer that never reads, and the vehicle's loop",
        "",
        f"One agent (onboard profile, synthetic camera 640x480 at {figures['fps']:g} fps, a goal"
        f" per frame {GOAL_DELAY_S * 1000:.0f} ms after it), {figures['seconds']:g} s in"
        f" {figures['rounds']} rounds of alternating phases: the Foxglove server up with nobody"
        " watching, and with a client subscribed to every channel that never reads.",
        "",
        "| phase | goal → Twist p50 (ms) | p95 (ms) | samples | the loop's CPU in the view"
        " (ms/s) |",
        "|---|---|---|---|---|",
    ]
    for phase in PHASES:
        found, cpu = figures.get(phase), figures[f"{phase} loop_ms_per_s"]
        if found is None:
            lines.append(f"| {phase} | not measured | | | {cpu} |")
        else:
            p50, p95, n = found["p50"], found["p95"], found["n"]
            lines.append(f"| {phase} | {p50:.2f} | {p95:.2f} | {n} | {cpu} |")
    increase = figures.get("p50_increase_pct")
    if increase is not None:
        verdict = "within" if increase <= MAX_P50_INCREASE_PCT else "beyond"
        lines.append(
            f"\np50 with the stuck viewer: {increase:+.1f} % ({verdict} the"
            f" {MAX_P50_INCREASE_PCT:g} % target); {figures['images']} images encoded for it."
        )
    path = out / "foxglove.md"
    path.write_text("\n".join(lines) + "\n")
    return path
