"""WebSocket ``/ws``: moves frames between sockets and the :class:`~app.signaling.hub.Hub`.

All rules live in the hub; :mod:`app.server.websocket` moves the frames, with the policy it
shares with ``/rosbridge`` (size limit, bounded outbox, JSON edge). This module adds what is
particular to signaling: the cap on connections, when a connection has logged in (its login
deadline and waiting budget are the shared adapter's) and the clock that ends sessions whose
token has expired.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from fastapi import APIRouter, WebSocket

from app.protocol.signaling import IceServer, IceTransportPolicy
from app.server.config import Settings
from app.server.turn import ice_servers_for
from app.server.websocket import (
    Outbox,
    Outboxes,
    SocketPolicy,
    client_address,
    login_deadline,
    refuse_if_full,
    serve,
)
from app.signaling.hub import Action, Census, Close, ConnId, Hub, HubMetrics, Outgoing

log = logging.getLogger(__name__)

router = APIRouter()

# How often sessions are checked for an expired token: a session ends at most this late.
EXPIRY_CHECK_S = 0.5


class HubPort(Protocol):
    """What the route needs of a hub: :class:`Hub`, or the fleet's Redis-backed one, which
    returns what it can decide at once and hands later actions to :meth:`Switchboard.dispatch`."""

    metrics: HubMetrics | None

    def connect(self) -> ConnId: ...
    def logged_in(self, conn: ConnId) -> bool: ...
    def receive(self, conn: ConnId, text: str) -> list[Action]: ...
    def receive_binary(self, conn: ConnId) -> list[Action]: ...
    def disconnect(self, conn: ConnId) -> list[Action]: ...
    def expire(self) -> list[Action]: ...
    def census(self) -> Census: ...


def login_ice(settings: Settings) -> Callable[[str], tuple[list[IceServer], IceTransportPolicy]]:
    """The ICE configuration each successful login gets: TURN credentials minted for it."""

    def ice(name: str) -> tuple[list[IceServer], IceTransportPolicy]:
        servers = ice_servers_for(settings, settings.ice_servers, name, time.time())
        return servers, settings.ice_transport_policy

    return ice


@dataclass
class Switchboard:
    """The hub plus the outbox of every open connection; lives on ``app.state.signaling``."""

    hub: HubPort
    policy: SocketPolicy
    max_connections: int = 256
    outboxes: Outboxes[ConnId] = field(init=False)

    def __post_init__(self) -> None:
        self.outboxes = Outboxes(self.policy, self.max_connections)

    @classmethod
    def from_settings(cls, settings: Settings, hub: HubPort | None = None) -> Switchboard:
        """A switchboard configured by ``settings`` around ``hub`` (default: a fresh ``Hub``)."""
        if hub is None:
            hub = Hub(
                secret=settings.secret,
                max_message_bytes=settings.max_message_bytes,
                ice=login_ice(settings),
            )
        return cls(
            hub,
            SocketPolicy.from_settings(settings),
            max_connections=settings.max_connections,
        )

    def open(self, address: str) -> tuple[ConnId, Outbox]:
        """Register a connection from ``address`` with the hub and give it an outbox; it is
        waiting (see :class:`~app.server.websocket.Outboxes`) until it logs in."""
        conn = self.hub.connect()
        return conn, self.outboxes.open(conn, address)

    def forget(self, conn: ConnId) -> None:
        """The connection is gone: tell the hub and deliver what that causes."""
        self.outboxes.forget(conn)
        self.dispatch(self.hub.disconnect(conn))

    async def expire_sessions(self) -> None:
        """Run until cancelled: every :data:`EXPIRY_CHECK_S`, end the sessions whose token
        has expired (the hub also ends one at its first frame after expiry)."""
        while True:
            await asyncio.sleep(EXPIRY_CHECK_S)
            self.dispatch(self.hub.expire())

    def dispatch(self, actions: list[Action]) -> None:
        """Queue each action on its connection's outbox (a login's answer ends its wait)."""
        for action in actions:
            outbox = self.outboxes.get(action.conn)
            if outbox is None:
                continue  # closed while this batch was being produced
            if self.hub.logged_in(action.conn):
                self.outboxes.authenticated(action.conn)
            match action:
                case Outgoing(message=message):
                    outbox.send(message)
                case Close(code=code, reason=reason):
                    outbox.close(code, reason)


@router.websocket("/ws")
async def signaling(websocket: WebSocket) -> None:
    """One signaling connection: frames in to the hub, the hub's messages out."""
    board: Switchboard = websocket.app.state.signaling
    await websocket.accept()
    if await refuse_if_full(websocket, board.outboxes, "connections"):
        return
    conn, outbox = board.open(client_address(websocket))

    def on_text(text: str) -> None:
        # The hub applies the same size limit (it is sans-I/O and tested without uvicorn).
        board.dispatch(board.hub.receive(conn, text))

    def on_binary(_data: bytes) -> None:
        board.dispatch(board.hub.receive_binary(conn))

    deadline = login_deadline(board.policy, lambda: board.hub.logged_in(conn), "login")
    try:
        await serve(
            websocket, outbox, on_text, on_binary, name=f"signaling-{conn}", deadline=deadline
        )
    finally:
        board.forget(conn)
