"""WebSocket client for the signaling server, as a vehicle (docs/architecture.md, "Signaling
protocol").

The login reply says when to renew the session's token (``renew_in``); the agent sends ``renew``
then and takes the fresh token from the ``renewed`` answer (:mod:`vehicle_agent.agent`).
"""

from __future__ import annotations

import asyncio
import json
import logging
import ssl
from collections.abc import AsyncIterator
from typing import Any

from pydantic import ValidationError
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI

from app.protocol.errors import describe
from app.protocol.rooms import Role
from app.protocol.signaling import IceServer, IceTransportPolicy, Leave, Login, LoginReply
from app.protocol.urls import ServerUrlError, untrusted_hint, ws_endpoint

log = logging.getLogger(__name__)

LOGIN_TIMEOUT_S = 10.0

Message = dict[str, Any]


class SignalingError(RuntimeError):
    """The signaling server could not be reached or refused us; the message says why."""


class LoginRefused(SignalingError):
    """The server answered the login with ``success: false``."""


def ws_url(server: str) -> str:
    """The ``/ws`` endpoint for a server base URL (``http://host:port`` or ``ws://.../ws``)."""
    try:
        return ws_endpoint(server)
    except ServerUrlError as exc:
        raise SignalingError(str(exc)) from None


class SignalingClient:
    """One logged-in signaling connection; iterate over it for the server's messages."""

    def __init__(
        self,
        server: str,
        name: str,
        room: str,
        role: Role = "vehicle",
        token: str | None = None,
        tls: ssl.SSLContext | None = None,
    ) -> None:
        self.url = ws_url(server)
        self.name = name
        self.room = room
        self.role = role
        self.token = token
        # Only for wss://; None there means the system's trusted CAs.
        self.tls = tls if self.url.startswith("wss:") else None
        self._ws: ClientConnection | None = None
        # From the login reply: the ICE servers (TURN credentials minted for this login) and
        # the transport policy every new peer connection uses ...
        self.ice_servers: list[IceServer] = []
        self.ice_transport_policy: IceTransportPolicy = "all"
        # ... and how soon to renew the token (None: the server asks for no tokens).
        self.renew_in: float | None = None

    async def connect(self) -> list[Message]:
        """Open the socket and log in; returns the room's roster (``[{name, role}]``)."""
        try:
            self._ws = await connect(
                self.url, open_timeout=LOGIN_TIMEOUT_S, max_size=2**20, ssl=self.tls
            )
        except (OSError, InvalidURI, InvalidHandshake, TimeoutError) as exc:
            raise SignalingError(
                f"cannot reach signaling server at {self.url}: {exc}{untrusted_hint(exc)}"
            ) from exc
        try:
            login = Login(
                type="login", name=self.name, role=self.role, room=self.room, token=self.token
            )
        except ValidationError as exc:
            await self.close()
            raise SignalingError(f"cannot log in as {self.name!r}: {describe(exc)}") from exc
        await self.send(login.model_dump(exclude_none=True))
        try:
            async with asyncio.timeout(LOGIN_TIMEOUT_S):
                reply = await self._receive()
        except (ConnectionClosed, TimeoutError) as exc:
            await self.close()
            raise SignalingError(f"no login answer from {self.url}: {exc}") from exc
        if reply.get("type") != "login":
            await self.close()
            raise SignalingError(f"unexpected answer to login from {self.url}: {reply}")
        if not reply.get("success"):
            await self.close()
            raise LoginRefused(f"login refused by {self.url}: {reply.get('reason')}")
        try:
            parsed = LoginReply.model_validate(reply)
        except ValidationError as exc:
            await self.close()
            raise SignalingError(f"malformed login answer from {self.url}: {exc}") from exc
        self.ice_servers = parsed.iceServers or []
        self.ice_transport_policy = parsed.iceTransportPolicy or "all"
        self.renew_in = parsed.renewIn
        return [p.model_dump() for p in parsed.peers]

    async def send(self, message: Message) -> None:
        """Send one message; a closed connection is left to the reader to notice."""
        if self._ws is None:
            raise SignalingError("not connected")
        try:
            await self._ws.send(json.dumps(message))
        except ConnectionClosed:
            log.debug("dropped %s: signaling connection closed", message.get("type"))

    async def _receive(self) -> Message:
        assert self._ws is not None
        while True:
            text = await self._ws.recv()
            try:
                message = json.loads(text)
            except json.JSONDecodeError:
                log.warning("signaling server sent malformed JSON: %.80r", text)
                continue
            if isinstance(message, dict) and isinstance(message.get("type"), str):
                return message
            log.warning("signaling server sent a message without a type: %.80r", text)

    async def messages(self) -> AsyncIterator[Message]:
        """The server's messages until the connection closes."""
        try:
            while True:
                yield await self._receive()
        except ConnectionClosed as exc:
            log.info("signaling connection closed: %s", exc)

    async def close(self) -> None:
        """Say goodbye (``leave``) and close the socket."""
        ws, self._ws = self._ws, None
        if ws is None:
            return
        try:
            await ws.send(Leave(type="leave").model_dump_json())
        except ConnectionClosed:
            pass
        await ws.close()
