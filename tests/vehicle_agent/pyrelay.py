"""A relay peer written with aiortc, for agent-level tests without a browser.

It speaks the same signaling (logs in as the room's relay, answers offers, trickles nothing:
aiortc puts its candidates in the SDP) and the same data-channel messages as the relay page, and
reads the frame tag of every decoded video frame. Its peer connection is a real one.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from typing import Any

from aiortc import RTCConfiguration, RTCPeerConnection, RTCSessionDescription
from aiortc.mediastreams import MediaStreamError, MediaStreamTrack
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from app.protocol import frametag
from app.protocol.channels import AUTOPILOT_CHANNEL

log = logging.getLogger(__name__)


class PyRelay:
    """The room's relay, minus the image analysis: tests send goals by hand."""

    def __init__(
        self, ws_url: str, room: str = "default", name: str = "relay", token: str | None = None
    ) -> None:
        self.ws_url, self.room, self.name, self.token = ws_url, room, name, token
        # Every signaling message received after the login, in order.
        self.signals: list[dict[str, Any]] = []
        self.pc: RTCPeerConnection | None = None
        self.channel: Any = None
        self.tags: list[int] = []
        self.messages: list[dict[str, Any]] = []
        self.offers = 0
        self._ws: ClientConnection | None = None
        self._tasks: set[asyncio.Task[None]] = set()
        self.changed = asyncio.Event()

    async def start(self) -> None:
        self._ws = await connect(self.ws_url)
        login = {"type": "login", "name": self.name, "role": "relay", "room": self.room}
        if self.token is not None:
            login["token"] = self.token
        await self._ws.send(json.dumps(login))
        reply = json.loads(await self._ws.recv())
        assert reply["success"], reply
        self._spawn(self._read(self._ws))

    def _spawn(self, coro: Any) -> None:
        task = asyncio.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _notify(self) -> None:
        self.changed.set()

    async def _read(self, ws: ClientConnection) -> None:
        with contextlib.suppress(ConnectionClosed):
            async for text in ws:
                message = json.loads(text)
                self.signals.append(message)
                if message["type"] == "offer":
                    await self._answer(ws, message)

    async def _answer(self, ws: ClientConnection, offer: dict[str, Any]) -> None:
        if self.pc is not None:
            await self.pc.close()
        self.offers += 1
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        self.pc = pc

        @pc.on("track")
        def _track(track: MediaStreamTrack) -> None:
            self._spawn(self._consume(track))

        @pc.on("datachannel")
        def _channel(channel: Any) -> None:
            # The reliable channel; the lossy state channel's pose lands in messages too.
            if channel.label == AUTOPILOT_CHANNEL:
                self.channel = channel

            @channel.on("message")
            def _message(text: str) -> None:
                self.messages.append(json.loads(text))
                self._notify()

            self._notify()

        await pc.setRemoteDescription(RTCSessionDescription(offer["sdp"], "offer"))
        await pc.setLocalDescription(await pc.createAnswer())
        answer = {"type": "answer", "to": offer["from"], "sdp": pc.localDescription.sdp}
        await ws.send(json.dumps(answer))

    async def _consume(self, track: MediaStreamTrack) -> None:
        with contextlib.suppress(MediaStreamError):
            while True:
                frame = await track.recv()
                tag = frametag.read(frame.to_ndarray(format="rgb24"))
                if tag is not None:
                    self.tags.append(tag)
                    self._notify()

    def send(self, message: dict[str, Any]) -> None:
        assert self.channel is not None and self.channel.readyState == "open"
        self.channel.send(json.dumps(message))

    async def until(self, condition: Any, timeout: float = 30.0) -> None:
        """Wait until ``condition()`` holds, re-checking whenever something arrives."""
        async with asyncio.timeout(timeout):
            while not condition():
                self.changed.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(0.2):
                        await self.changed.wait()

    async def leave(self) -> None:
        """Leave the room the way a page does: ``leave``, then close everything."""
        if self._ws is not None:
            with contextlib.suppress(ConnectionClosed):
                await self._ws.send(json.dumps({"type": "leave"}))
            await self._ws.close()
            self._ws = None
        if self.pc is not None:
            await self.pc.close()
            self.pc = None
        self.channel = None
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
