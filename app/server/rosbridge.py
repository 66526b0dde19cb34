"""WebSocket ``/rosbridge`` and ``GET /turtlesim/state``, plus the task that steps the simulator.

The rules live in :mod:`app.turtlesim.rosbridge`; :mod:`app.server.websocket` moves the frames
with the policy it shares with ``/ws`` (size limit, bounded outbox, JSON edge). Every tick the
simulator steps and each connection's writer is woken; a writer that is free then takes its
session's publications (the latest of each subscription), so the tick costs the same whatever
the clients subscribe to, and a client that does not read is sent nothing and slows no one.
The tick is fixed at :attr:`TurtleSim.TICK_S` (16 ms, turtlesim's own): the simulator advances
that much per step, so pacing the loop any other way would only change the turtle's speed.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import asdict
from typing import Any

from fastapi import APIRouter, HTTPException, Request, WebSocket, status

from app.protocol.close_codes import CloseCode
from app.protocol.jsonedge import oversize
from app.protocol.ros import DEFAULT_FLAVOUR, RosFlavour
from app.server.access import RosbridgeGate, bearer_token, state_refusal
from app.server.config import Settings
from app.server.metrics import ServerMetrics
from app.server.websocket import Outbox, Outboxes, SocketPolicy, refuse_if_full, serve
from app.turtlesim.rosbridge import (
    Publish,
    Refused,
    RosbridgeHub,
    RosbridgeSession,
    parse_frame,
)
from app.turtlesim.sim import TurtleSim

log = logging.getLogger(__name__)

router = APIRouter()

# If the tick task falls this far behind the wall clock it skips ahead instead of catching up.
MAX_LAG_S = 0.5


class Simulator:
    """The turtle simulator, its rosbridge hub, and the task that steps them.

    Lives on ``app.state.simulator``; ``app.state.turtlesim`` is its :class:`TurtleSim`.
    """

    def __init__(
        self, policy: SocketPolicy, max_sessions: int = 64, ros: RosFlavour = DEFAULT_FLAVOUR
    ) -> None:
        self.sim = TurtleSim()
        self.hub = RosbridgeHub(self.sim, ros)
        self.tick_s = TurtleSim.TICK_S
        self.policy = policy
        self.outboxes: Outboxes[RosbridgeSession] = Outboxes(policy, max_sessions)
        self._task: asyncio.Task[None] | None = None

    @classmethod
    def from_settings(cls, settings: Settings) -> Simulator:
        """A fresh simulator with the socket policy and session cap of ``settings``."""
        return cls(
            SocketPolicy.from_settings(settings), settings.max_rosbridge_sessions, settings.ros
        )

    def start(self) -> None:
        """Start stepping the simulator every ``tick_s`` of wall time."""
        self._task = asyncio.create_task(self._run(), name="turtlesim-tick")
        self._task.add_done_callback(_report_crash)

    async def stop(self) -> None:
        """Stop the tick task and wait for it."""
        if self._task is None:
            return
        self._task.cancel()
        await asyncio.gather(self._task, return_exceptions=True)
        self._task = None

    def open(self) -> tuple[RosbridgeSession, Outbox]:
        """A new rosbridge client: its session and outbox."""
        session = self.hub.open_session()
        return session, self.outboxes.open(session, pull=session.take_frames)

    def forget(self, session: RosbridgeSession) -> None:
        """The client is gone: its subscriptions go with it."""
        session.close()
        self.outboxes.forget(session)

    def state(self) -> dict[str, Any]:
        """The turtles' poses and pens and the pen strokes, as JSON-ready data."""
        turtles = [
            {"name": name, **asdict(self.sim.pose(name)), "pen": asdict(self.sim.pen(name))}
            for name in self.sim.names()
        ]
        strokes = [
            {"turtle": s.turtle, "pen": asdict(s.pen), "points": s.points}
            for s in self.sim.strokes()
        ]
        return {
            "world_size": TurtleSim.WORLD_SIZE,
            "tick": self.sim.ticks,
            "turtles": turtles,
            "strokes": strokes,
        }

    def tick(self) -> None:
        """One step: the simulator, then a word to every writer that new poses are there."""
        self.sim.step()
        self.hub.tick(time.monotonic())
        self.wake()

    def wake(self) -> None:
        """Tell every writer there may be something new to send (a tick, a publication)."""
        for _, outbox in self.outboxes.items():
            outbox.wake()

    async def _run(self) -> None:
        next_at = time.monotonic()
        while True:
            self.tick()
            next_at += self.tick_s
            delay = next_at - time.monotonic()
            if delay < -MAX_LAG_S:
                log.warning("simulator tick %.0f ms late; skipping ahead", -delay * 1000)
                next_at = time.monotonic()
                delay = 0.0
            await asyncio.sleep(max(delay, 0.0))


@router.get("/turtlesim/state")
async def turtlesim_state(request: Request) -> dict[str, Any]:
    """Read-only view of the simulator: poses, pens and pen strokes (a token of any role)."""
    refusal = state_refusal(
        request.app.state.settings.secret, bearer_token(request.headers), time.time()
    )
    if refusal is not None:
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, refusal, {"WWW-Authenticate": "Bearer"})
    simulator: Simulator = request.app.state.simulator
    return simulator.state()


@router.websocket("/rosbridge")
async def rosbridge(websocket: WebSocket) -> None:
    """One rosbridge v2 client (roslibpy, roslib.js): JSON text frames from it; JSON text, or
    CBOR binary frames for a subscription that asks, to it."""
    simulator: Simulator = websocket.app.state.simulator
    metrics: ServerMetrics = websocket.app.state.metrics
    gate = RosbridgeGate(websocket.app.state.settings.secret)
    refusal = gate.handshake(bearer_token(websocket.headers), time.time())
    if refusal is not None:
        log.info("rosbridge handshake refused: %s", refusal)
        metrics.refused("auth")
        await websocket.close(CloseCode.POLICY_VIOLATION)  # before accept(): HTTP 403
        return
    await websocket.accept()
    if await refuse_if_full(websocket, simulator.outboxes, "rosbridge clients"):
        return
    session, outbox = simulator.open()

    def on_text(text: str) -> None:
        closing: tuple[int, str] | None = None
        if (reason := oversize(text, simulator.policy.max_message_bytes)) is not None:
            metrics.refused("invalid")
            replies = session.error(reason)
        else:
            frame = parse_frame(text)
            decision = gate.check(frame, time.time())
            if decision.forward and isinstance(frame, Refused):
                metrics.refused("invalid")
            if session.room is None and gate.claims is not None:
                session.room = gate.claims.room  # its camera topics are its room's
            replies = session.handle(frame) if decision.forward else []
            if decision.forward and isinstance(frame, Publish):
                simulator.wake()  # a camera image goes out now, not at the next tick
            if decision.reply is not None:  # the gate replies only to refuse: no token, or a
                metrics.refused("auth")  # role that may not do this
                replies.append(decision.reply)
            closing = decision.close
        for reply in replies:
            outbox.send(reply)
        if closing is not None:
            outbox.close(*closing)  # after the refusal's reason

    def on_binary(_data: bytes) -> None:
        metrics.refused("invalid")
        for reply in session.error("binary frames are not supported: send JSON text"):
            outbox.send(reply)

    async def end_at_expiry() -> None:
        """Close the connection once its token has expired (a renewal moves the time on)."""
        while True:
            expires_at = gate.expires_at
            await asyncio.sleep(1.0 if expires_at is None else max(0.0, expires_at - time.time()))
            if (expired := gate.expiry(time.time())) is not None:
                metrics.refused("auth")
                assert expired.reply is not None and expired.close is not None
                outbox.send(expired.reply)
                outbox.close(*expired.close)
                return

    watchdog = None
    if gate.secret is not None:
        watchdog = asyncio.create_task(end_at_expiry(), name="rosbridge-expiry")
    try:
        await serve(websocket, outbox, on_text, on_binary, name="rosbridge")
    finally:
        if watchdog is not None:
            watchdog.cancel()
        simulator.forget(session)


def _report_crash(task: asyncio.Task[None]) -> None:
    # Cancelling and gathering hides a task's own failure; log it here instead.
    if not task.cancelled() and (error := task.exception()) is not None:
        log.error("%s died", task.get_name(), exc_info=error)
