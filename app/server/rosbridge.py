"""WebSocket ``/rosbridge`` and ``GET /turtlesim/state``, plus the task that steps the simulator.

The rules live in :mod:`app.turtlesim.rosbridge`; this module only moves text frames between
sockets and sessions. Every tick the simulator steps, the hub offers each turtle's pose to the
subscribers, and each connection's publications go to its outbox, which a writer task drains, so
one slow client never holds up the tick or the other clients.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from dataclasses import asdict
from typing import Any

from fastapi import APIRouter, Request, WebSocket
from starlette.websockets import WebSocketDisconnect, WebSocketDisconnected

from app.turtlesim.rosbridge import RosbridgeHub, RosbridgeSession
from app.turtlesim.sim import TurtleSim

log = logging.getLogger(__name__)

router = APIRouter()

# Publications waiting for a slow reader beyond this are dropped (poses are superseded every
# tick anyway); replies to the client's own requests are always queued.
OUTBOX_LIMIT = 512
# If the tick task falls this far behind the wall clock it skips ahead instead of catching up.
MAX_LAG_S = 0.5


class Simulator:
    """The turtle simulator, its rosbridge hub, and the task that steps them.

    Lives on ``app.state.simulator``; ``app.state.turtlesim`` is its :class:`TurtleSim`.
    """

    def __init__(self, tick_s: float = TurtleSim.TICK_S, max_message_bytes: int = 64 * 1024):
        self.sim = TurtleSim()
        self.hub = RosbridgeHub(self.sim)
        self.tick_s = tick_s
        self.max_message_bytes = max_message_bytes
        self._outboxes: dict[RosbridgeSession, asyncio.Queue[str]] = {}
        self._task: asyncio.Task[None] | None = None

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

    def open(self) -> tuple[RosbridgeSession, asyncio.Queue[str]]:
        """A new rosbridge client: its session and outbox."""
        session = self.hub.open_session()
        outbox: asyncio.Queue[str] = asyncio.Queue()
        self._outboxes[session] = outbox
        return session, outbox

    def forget(self, session: RosbridgeSession) -> None:
        """The client is gone: its subscriptions go with it."""
        session.close()
        self._outboxes.pop(session, None)

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
        """One step: the simulator, then the publications it causes."""
        self.sim.step()
        self.hub.tick(time.monotonic())
        for session, outbox in self._outboxes.items():
            publications = session.take_publications()
            room = OUTBOX_LIMIT - outbox.qsize()
            if len(publications) > room:
                log.debug("rosbridge client too slow: %d publications dropped", len(publications))
                publications = publications[:room] if room > 0 else []
            for publication in publications:
                outbox.put_nowait(json.dumps(publication))

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
    """Read-only view of the simulator: poses, pens and pen strokes."""
    simulator: Simulator = request.app.state.simulator
    return simulator.state()


@router.websocket("/rosbridge")
async def rosbridge(websocket: WebSocket) -> None:
    """One rosbridge v2 client (roslibpy, roslib.js): JSON text frames both ways."""
    simulator: Simulator = websocket.app.state.simulator
    await websocket.accept()
    session, outbox = simulator.open()
    writer = asyncio.create_task(_write(websocket, outbox), name="rosbridge-writer")
    writer.add_done_callback(_report_crash)
    try:
        while not writer.done():
            frame = await websocket.receive()
            if frame["type"] == "websocket.disconnect":
                break
            text = frame.get("text")
            size = len(text.encode()) if text is not None else 0
            if text is None:
                replies = session.error("binary frames are not supported: send JSON text")
            elif size > simulator.max_message_bytes:
                replies = session.error(
                    f"message of {size} bytes exceeds the limit of {simulator.max_message_bytes}"
                )
            else:
                replies = session.receive(text)
            for reply in replies:
                outbox.put_nowait(json.dumps(reply))
    finally:
        simulator.forget(session)
        writer.cancel()
        await asyncio.gather(writer, return_exceptions=True)


def _report_crash(task: asyncio.Task[None]) -> None:
    # Cancelling and gathering hides a task's own failure; log it here instead.
    if not task.cancelled() and (error := task.exception()) is not None:
        log.error("%s died", task.get_name(), exc_info=error)


async def _write(websocket: WebSocket, outbox: asyncio.Queue[str]) -> None:
    """Send queued frames in order until the socket is gone."""
    try:
        while True:
            await websocket.send_text(await outbox.get())
    except (WebSocketDisconnect, WebSocketDisconnected):
        return
