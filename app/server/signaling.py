"""WebSocket ``/ws``: moves frames between sockets and the :class:`~app.signaling.hub.Hub`.

All rules live in the hub; this module only reads frames, hands them over, and delivers what the
hub returns. Each connection has a bounded outbox drained by its own writer task, so one slow
peer never holds up the others and messages to a peer keep their order.
"""

from __future__ import annotations

import asyncio
import json
import logging
from dataclasses import dataclass, field
from typing import Any, Protocol

from fastapi import APIRouter, WebSocket
from starlette.websockets import WebSocketDisconnect, WebSocketDisconnected

from app.server.config import Settings
from app.signaling.hub import Action, Close, ConnId, Hub, Outgoing

log = logging.getLogger(__name__)

router = APIRouter()

# Close code for a peer that does not read its messages fast enough (RFC 6455: "try again later").
CLOSE_TRY_AGAIN_LATER = 1013


@dataclass(frozen=True)
class _Shut:
    code: int
    reason: str


_OutboxItem = dict[str, Any] | _Shut


class HubPort(Protocol):
    """What the route needs of a hub: :class:`Hub`, or the fleet's Redis-backed one, which
    returns what it can decide at once and hands later actions to :meth:`Switchboard.dispatch`."""

    def connect(self) -> ConnId: ...
    def receive(self, conn: ConnId, text: str) -> list[Action]: ...
    def receive_binary(self, conn: ConnId) -> list[Action]: ...
    def disconnect(self, conn: ConnId) -> list[Action]: ...


@dataclass
class Switchboard:
    """The hub plus the outbox of every open connection; lives on ``app.state.signaling``."""

    hub: HubPort
    # Messages waiting for a slow reader; past this the reader is closed rather than buffered.
    outbox_limit: int = 256
    _outboxes: dict[ConnId, asyncio.Queue[_OutboxItem]] = field(default_factory=dict, init=False)

    @classmethod
    def from_settings(cls, settings: Settings) -> Switchboard:
        """A switchboard around a fresh hub configured by ``settings``."""
        return cls(Hub(token=settings.token, max_message_bytes=settings.max_message_bytes))

    def open(self) -> tuple[ConnId, asyncio.Queue[_OutboxItem]]:
        """Register a connection with the hub and give it an outbox."""
        conn = self.hub.connect()
        outbox: asyncio.Queue[_OutboxItem] = asyncio.Queue(self.outbox_limit)
        self._outboxes[conn] = outbox
        return conn, outbox

    def forget(self, conn: ConnId) -> None:
        """The connection is gone: tell the hub and deliver what that causes."""
        self._outboxes.pop(conn, None)
        self.dispatch(self.hub.disconnect(conn))

    def dispatch(self, actions: list[Action]) -> None:
        """Queue each action on its connection's outbox."""
        for action in actions:
            outbox = self._outboxes.get(action.conn)
            if outbox is None:
                continue  # closed while this batch was being produced
            match action:
                case Outgoing(message=message):
                    item: _OutboxItem = message
                case Close(code=code, reason=reason):
                    item = _Shut(code, reason)
            try:
                outbox.put_nowait(item)
            except asyncio.QueueFull:
                log.warning("closing %s: %d messages unread", action.conn, outbox.qsize())
                while not outbox.empty():
                    outbox.get_nowait()
                outbox.put_nowait(_Shut(CLOSE_TRY_AGAIN_LATER, "too many unread messages"))
                # Nothing more for it: its writer closes the socket, its reader then leaves.
                del self._outboxes[action.conn]


@router.websocket("/ws")
async def signaling(websocket: WebSocket) -> None:
    """One signaling connection: frames in to the hub, the hub's messages out."""
    board: Switchboard = websocket.app.state.signaling
    await websocket.accept()
    conn, outbox = board.open()
    writer = asyncio.create_task(_write(websocket, outbox), name=f"signaling-writer-{conn}")
    closing = False
    try:
        while not writer.done():
            frame = await websocket.receive()
            if frame["type"] == "websocket.disconnect":
                break
            text = frame.get("text")
            if text is not None:
                actions = board.hub.receive(conn, text)
            else:
                actions = board.hub.receive_binary(conn)
            board.dispatch(actions)
            if any(isinstance(a, Close) and a.conn == conn for a in actions):
                closing = True
                break
    finally:
        board.forget(conn)
        await _finish(writer, flush=closing)


async def _finish(writer: asyncio.Task[None], *, flush: bool) -> None:
    """Stop the writer: after it has sent its last messages and the close, if ``flush``."""
    if not flush:
        writer.cancel()  # the socket is gone; nothing left to deliver
    done, _ = await asyncio.wait([writer], timeout=5)
    if not done:
        log.warning("signaling writer did not finish within 5 s; cancelling it")
        writer.cancel()
    elif not writer.cancelled() and (error := writer.exception()) is not None:
        raise error


async def _write(websocket: WebSocket, outbox: asyncio.Queue[_OutboxItem]) -> None:
    """Send queued messages in order until told to close or the socket is gone."""
    try:
        while True:
            item = await outbox.get()
            if isinstance(item, _Shut):
                await websocket.close(item.code, item.reason)
                return
            await websocket.send_text(json.dumps(item))
    except (WebSocketDisconnect, WebSocketDisconnected):
        return
