"""Foxglove viewers for ``autopilot bench --foxglove``: one that subscribes to every channel and
then never reads, and one that reads everything in a process of its own (so that its reading
costs the agent's process nothing but the sending):

    python -m app.tools.bench.foxglove_viewer URL CHANNELS

reads lines on stdin: ``watch`` connects, subscribes to every channel and answers ``watching``,
then reads and drops every message; ``leave`` closes and answers ``left``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import sys
from collections.abc import AsyncIterator
from typing import Any, Final

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

# The reading viewer process's niceness.
VIEWER_NICENESS: Final = 10
# The subprotocols a Foxglove client offers the SDK's server.
SUBPROTOCOLS: Final[Any] = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


async def subscribe_all(ws: ClientConnection, channels_expected: int) -> None:
    """Subscribe to every channel the server advertises, once ``channels_expected`` came."""
    ids: list[int] = []
    async with asyncio.timeout(5):
        while len(ids) < channels_expected:
            # Nothing binary comes before a subscription.
            message = json.loads(await ws.recv())
            if message.get("op") == "advertise":
                ids += [channel["id"] for channel in message["channels"]]
    subscribe = [{"id": i, "channelId": c} for i, c in enumerate(ids)]
    await ws.send(json.dumps({"op": "subscribe", "subscriptions": subscribe}))


@contextlib.asynccontextmanager
async def stuck_viewer(url: str, channels_expected: int) -> AsyncIterator[None]:
    """A Foxglove client subscribed to every channel that reads nothing more (its library reads
    a frame ahead, then leaves the socket unread)."""
    # Closing: the server answers the close frame after what it queued, which is never read.
    async with connect(url, subprotocols=SUBPROTOCOLS, max_queue=1, close_timeout=0.5) as ws:
        await subscribe_all(ws, channels_expected)
        yield


class ReadingViewer:
    """A viewer that reads every channel, in a process of its own (this module's ``main``)."""

    def __init__(self, process: asyncio.subprocess.Process) -> None:
        self._process = process

    async def _say(self, line: str, answer: str) -> None:
        assert self._process.stdin is not None and self._process.stdout is not None
        self._process.stdin.write(f"{line}\n".encode())
        await self._process.stdin.drain()
        async with asyncio.timeout(10):
            heard = (await self._process.stdout.readline()).decode().strip()
        if heard != answer:
            raise RuntimeError(f"the reading viewer answered {heard!r} to {line!r}")

    @contextlib.asynccontextmanager
    async def watching(self) -> AsyncIterator[None]:
        """Subscribed to every channel and reading, until the block ends."""
        await self._say("watch", "watching")
        try:
            yield
        finally:
            await self._say("leave", "left")


@contextlib.asynccontextmanager
async def reading_viewer(url: str, channels_expected: int) -> AsyncIterator[ReadingViewer]:
    """The process of a :class:`ReadingViewer` of ``url``, until the block ends."""
    process = await asyncio.create_subprocess_exec(
        sys.executable, "-m", __name__, url, str(channels_expected),
        stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        yield ReadingViewer(process)
    finally:
        if process.returncode is None:
            process.kill()
        await process.wait()


async def _serve(url: str, channels_expected: int) -> None:
    loop = asyncio.get_running_loop()
    stdin = asyncio.StreamReader()
    await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(stdin), sys.stdin)
    watching: tuple[ClientConnection, asyncio.Task[None]] | None = None
    while line := (await stdin.readline()).decode().strip():
        if line == "watch" and watching is None:
            ws = await connect(url, subprotocols=SUBPROTOCOLS, max_size=None)
            await subscribe_all(ws, channels_expected)
            watching = ws, asyncio.create_task(_drain(ws))
            _answer("watching")
        elif line == "leave" and watching is not None:
            ws, reading = watching
            await ws.close()
            await reading
            watching = None
            _answer("left")


async def _drain(ws: ClientConnection) -> None:
    # The SDK's server ends a connection without answering its close frame.
    with contextlib.suppress(ConnectionClosed):
        async for _ in ws:
            pass


def _answer(text: str) -> None:
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


if __name__ == "__main__":
    # A real viewer runs on another machine: below the agent here, where the cores are shared.
    os.setpriority(os.PRIO_PROCESS, 0, VIEWER_NICENESS)
    asyncio.run(_serve(sys.argv[1], int(sys.argv[2])))
