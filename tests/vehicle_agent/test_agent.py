"""The agent over real signaling and a real WebRTC link to a relay peer written with aiortc.

Run inside the private network namespace: ``scripts/in-netns python -m pytest tests/vehicle_agent``.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import socket
import time
from collections.abc import AsyncIterator, Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest

from app.protocol import tokens
from app.protocol.events import AnyEvent, DriveReceived, FrameSent, TwistSent
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from tests.helpers.sockets import rosbridge_url
from tests.helpers.waiting import eventually
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.events import EventLog
from vehicle_agent.robotlink import RosbridgeLink, SimLink
from vehicle_agent.rosbridge_client import RosbridgeClient
from vehicle_agent.video import FixedPath, SyntheticVideo

from .pyrelay import PyRelay

W, H = 320, 240
LEFT = (0.2 * W, 0.42 * H)  # a face left of centre, a little above the middle
RIGHT = (0.8 * W, 0.42 * H)


@dataclass
class Running:
    agent: Agent
    turtle: SimLink
    events: list[AnyEvent]

    def heading_deg(self) -> float:
        return math.degrees(self.turtle.sim.pose("turtle1").theta)

    def twists(self) -> list[TwistSent]:
        return [e for e in self.events if isinstance(e, TwistSent)]


@contextlib.asynccontextmanager
async def running_agent(server_url: str, **config: Any) -> AsyncIterator[Running]:
    events: list[AnyEvent] = []
    log = EventLog()
    log.listeners.append(events.append)
    video = SyntheticVideo(W, H, fps=15, path=FixedPath(0.5, 0.5), on_frame=log.emit)
    turtle = SimLink()
    agent = Agent(AgentConfig(server=server_url, **config), video, turtle, log)
    task = asyncio.create_task(agent.run())
    try:
        async with asyncio.timeout(10):
            await agent.logged_in.wait()
        yield Running(agent, turtle, events)
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


@contextlib.asynccontextmanager
async def relay_in(server: RunningServer) -> AsyncIterator[PyRelay]:
    relay = PyRelay(server.ws_url)
    await relay.start()
    try:
        yield relay
    finally:
        await relay.leave()


async def connected(relay: PyRelay) -> None:
    """Video frames are decoded at the relay and the data channel is open."""
    await relay.until(
        lambda: (
            len(relay.tags) >= 3
            and relay.channel is not None
            and relay.channel.readyState == "open"
        )
    )


async def pilot_until(
    relay: PyRelay, target: tuple[float, float], done: Callable[[], bool], timeout: float = 20
) -> int:
    """Send goals at 20 Hz (like the relay's snapshot loop) until ``done()``; returns last seq."""
    seq = 0
    async with asyncio.timeout(timeout):
        while not done():
            seq += 1
            relay.send(
                {
                    "type": "goal",
                    "seq": seq,
                    "op": "face",
                    "x": target[0],
                    "y": target[1],
                    "w": W,
                    "h": H,
                    # The relay's clock at sending: goals held back too long are stale.
                    "t": time.time() * 1000,
                    "frame": relay.tags[-1] if relay.tags else None,
                }
            )
            await asyncio.sleep(0.05)
    return seq


async def test_agent_streams_tagged_video_and_pose_telemetry(server: RunningServer) -> None:
    async with running_agent(server.url), relay_in(server) as relay:
        await connected(relay)
        # Tags decoded after VP8/H264 come in order: the frame number survives the codec.
        assert relay.tags == sorted(relay.tags)
        await relay.until(lambda: any(m["type"] == "pose" for m in relay.messages))
        pose = next(m for m in relay.messages if m["type"] == "pose")
        assert pose["x"] == pytest.approx(5.544445, abs=1e-3)
        assert {"y", "theta", "t"} <= pose.keys()


async def test_the_relay_learns_when_each_frame_it_decodes_was_captured(
    server: RunningServer,
) -> None:
    async with running_agent(server.url) as run, relay_in(server) as relay:
        await connected(relay)

        def captured() -> dict[int, float]:
            batches = [m for m in relay.messages if m["type"] == "frameTimes"]
            return {f["frame"]: f["t"] for m in batches for f in m["frames"]}

        await relay.until(lambda: relay.tags[-1] in captured())
        # When the frame was handed to the encoder (its frame_sent event), on the wall clock,
        # which a client on this machine can compare with its own.
        wall_minus_monotonic = time.time() - time.monotonic()
        sent = {e.frame: e.t for e in run.events if isinstance(e, FrameSent)}
        for frame, t_ms in captured().items():
            assert t_ms / 1000 == pytest.approx(sent[frame] + wall_minus_monotonic, abs=0.02)
        assert captured()[relay.tags[-1]] < time.time() * 1000


async def test_goals_turn_the_turtle_to_the_face_and_stop_zeroes(server: RunningServer) -> None:
    async with running_agent(server.url) as run, relay_in(server) as relay:
        await connected(relay)
        # The spawn step turned the turtle to face up before any goal came.
        await eventually(lambda: run.heading_deg() == pytest.approx(90.0))
        # Face on the left, a little above the middle: the turtle turns to look left-up.
        await pilot_until(relay, LEFT, lambda: 150 < run.heading_deg() <= 180)
        # The face moves to the right: the turtle follows, the short way back.
        await pilot_until(relay, RIGHT, lambda: 0 < run.heading_deg() < 30)
        # Each Twist names the goal (and so the video frame) that caused it.
        last = run.twists()[-1]
        assert last.seq is not None and last.frame in relay.tags
        relay.send({"type": "stop"})
        await eventually(lambda: run.twists()[-1].angular == 0.0 and run.twists()[-1].seq is None)
        settled = run.heading_deg()
        await asyncio.sleep(0.5)
        assert run.heading_deg() == pytest.approx(settled, abs=0.01)


async def test_goal_timeout_stops_the_turtle(server: RunningServer) -> None:
    async with running_agent(server.url) as run, relay_in(server) as relay:
        await connected(relay)
        # Keep the face far from where the turtle looks, so it is still turning when goals stop.
        await pilot_until(relay, LEFT, lambda: run.heading_deg() > 120)
        last_goal = asyncio.get_running_loop().time()
        await eventually(lambda: run.twists()[-1].seq is None, timeout=5)
        stopped_after = asyncio.get_running_loop().time() - last_goal
        # The default timeout (0.7 s) wakes the ticker on time; room for a loaded machine.
        assert 0.6 < stopped_after < 1.5
        settled = run.heading_deg()
        await asyncio.sleep(0.5)
        assert run.heading_deg() == pytest.approx(settled, abs=0.01)


async def test_the_dead_man_stops_the_turtle_0_3_s_after_the_last_drive_command(
    server: RunningServer,
) -> None:
    # The operator takes the wheel and holds a key (its command resent every 0.1 s, as the
    # client does), then falls silent. The contract is 0.3 s from the last command to the zero
    # Twist (docs/contracts.md), written here as a number; measured on the agent's own event
    # stamps, so the link's delay is not in it, only the agent's timer (0.05 s to spare).
    async with running_agent(server.url) as run, relay_in(server) as relay:
        await connected(relay)
        relay.send({"type": "mode", "mode": "manual", "operator": "ann", "reason": "taken over"})
        for seq in range(1, 6):
            relay.send({"type": "drive", "seq": seq, "linear": 0, "angular": 1})
            await asyncio.sleep(0.1)
        await eventually(lambda: len(drives(run)) == 5, timeout=5, what="five drive commands")
        last = drives(run)[-1].t
        await eventually(lambda: stops_after(run, last) != [], timeout=5, what="the dead-man")
        # Held, the key kept the turtle moving: no zero Twist between its commands.
        assert stops_after(run, drives(run)[0].t) == stops_after(run, last)
        # The drive event is stamped with the time the dead-man counts from.
        assert 0.3 <= stops_after(run, last)[0].t - last <= 0.3 + 0.05
        settled = run.heading_deg()
        await asyncio.sleep(0.3)
        assert run.heading_deg() == pytest.approx(settled, abs=0.01)


def drives(run: Running) -> list[DriveReceived]:
    """The drive commands the agent applied."""
    return [e for e in run.events if isinstance(e, DriveReceived) and e.applied]


def stops_after(run: Running, t: float) -> list[TwistSent]:
    """The zero Twists published after ``t`` (monotonic seconds)."""
    return [
        e for e in run.twists() if e.t > t and e.seq is None and e.linear == 0 and e.angular == 0
    ]


async def test_malformed_channel_messages_get_an_error_and_are_dropped(
    server: RunningServer,
) -> None:
    async with running_agent(server.url) as run, relay_in(server) as relay:
        await connected(relay)
        relay.channel.send("{not json")
        relay.send({"type": "dance"})
        relay.send(
            {"type": "goal", "seq": 1, "op": "face", "x": "left", "y": 1, "w": W, "h": H, "t": 0}
        )
        relay.send({"type": "goal", "seq": 2, "op": "face", "x": 1, "y": 1, "w": 0, "h": H, "t": 0})
        await relay.until(lambda: sum(m["type"] == "error" for m in relay.messages) >= 4)
        errors = [m for m in relay.messages if m["type"] == "error"]
        assert "malformed JSON" in errors[0]["reason"]
        assert errors[1]["ref"] == "dance" and "dance" in errors[1]["reason"]
        assert errors[2]["ref"] == "goal" and "x" in errors[2]["reason"]
        assert errors[3]["ref"] == "goal" and "w" in errors[3]["reason"]
        assert run.twists() == []
        # The link survives bad input: a good goal still turns the turtle.
        await pilot_until(relay, LEFT, lambda: run.heading_deg() > 120)


async def test_relay_leaving_stops_the_turtle_and_a_new_relay_pilots_again(
    server: RunningServer,
) -> None:
    async with running_agent(server.url) as run:
        async with relay_in(server) as relay:
            await connected(relay)
            await pilot_until(relay, LEFT, lambda: run.heading_deg() > 120)
            left_at = asyncio.get_running_loop().time()
        # The relay left while goals were flowing: zero Twist at once, not after the timeout.
        await eventually(lambda: run.twists()[-1].seq is None, timeout=5)
        assert asyncio.get_running_loop().time() - left_at < 0.6
        async with relay_in(server) as relay:
            await connected(relay)
            await pilot_until(relay, RIGHT, lambda: 0 < run.heading_deg() < 30)


def serve_on(port: int) -> RunningServer:
    """The app on a given port: a restarted server must come back where the agent expects it."""
    return start_in_thread(Settings(), port=port)


@pytest.fixture
def free_port() -> Iterator[int]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    yield port


async def test_agent_survives_a_signaling_server_restart(free_port: int) -> None:
    first = await asyncio.to_thread(serve_on, free_port)
    try:
        async with running_agent(first.url) as run:
            async with relay_in(first) as relay:
                await connected(relay)
                await pilot_until(relay, LEFT, lambda: run.heading_deg() > 120)
                await asyncio.to_thread(first.stop)
                await eventually(lambda: run.twists()[-1].seq is None, timeout=5)
                await eventually(lambda: not run.agent.logged_in.is_set(), timeout=5)
            second = await asyncio.to_thread(serve_on, free_port)
            try:
                async with asyncio.timeout(30):
                    await run.agent.logged_in.wait()
                async with relay_in(second) as relay:
                    await connected(relay)
                    await pilot_until(relay, RIGHT, lambda: 0 < run.heading_deg() < 30)
            finally:
                await asyncio.to_thread(second.stop)
    finally:
        first.stop()


@pytest.mark.slow
async def test_a_renewing_agent_keeps_its_session_and_media_past_several_token_lifetimes(
    start_server: Callable[[Settings], RunningServer],
) -> None:
    """The agent renews before its vehicle token expires, on ``/ws`` and on the
    server's ``/rosbridge``, without dropping its link: the same peer connection carries video
    and goals through several lifetimes of its tokens, and goals still drive the turtle."""
    secret = "agent-renewal-test-secret"
    server = start_server(Settings(environment="development", secret=secret))
    lifetime = 6.0  # long enough for the turtle to connect on a loaded machine
    first = tokens.sign(secret, "default", "vehicle", now=time.time(), ttl_s=lifetime)
    turtle = RosbridgeLink(RosbridgeClient(rosbridge_url(server), token=first))
    video = SyntheticVideo(W, H, fps=15, path=FixedPath(0.5, 0.5))
    agent = Agent(AgentConfig(server=server.url, token=first), video, turtle, EventLog())
    task = asyncio.create_task(agent.run())
    relay = PyRelay(
        server.ws_url, token=tokens.sign(secret, "default", "relay", now=time.time(), ttl_s=600)
    )
    try:
        async with asyncio.timeout(10):
            await agent.logged_in.wait()
        await relay.start()
        await connected(relay)
        await asyncio.sleep(3 * lifetime)
        frames = len(relay.tags)
        await asyncio.sleep(lifetime)
        assert len(relay.tags) > frames  # video still arrives, a fourth lifetime on
        assert agent.token is not None
        renewed = tokens.verify(secret, agent.token, now=time.time())
        assert renewed.exp > tokens.verify(secret, first, now=0).exp + 3 * lifetime - 1
        # One login, one offer, one peer connection: nothing was dropped and joined again.
        assert relay.offers == 1
        assert not [m for m in relay.signals if m["type"] == "leave"]
        # The rosbridge session that drives the turtle lives on too: a goal turns it.
        assert agent.pose is not None
        await pilot_until(relay, LEFT, lambda: agent.pose is not None and agent.pose.theta > 2.0)
    finally:
        await relay.leave()
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
