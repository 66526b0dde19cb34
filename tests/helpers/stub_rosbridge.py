"""A rosbridge of the test's own: it records every op a client sends, answers rosapi's
``topic_type`` and the services it is given, and sends the test's frames (any frame at all, bad
ones included) to the last connection."""

from __future__ import annotations

import contextlib
import json
from collections.abc import AsyncIterator, Callable
from typing import Any

import cbor2
from websockets.asyncio.server import Server, ServerConnection, serve

from app.protocol import jsonedge

# A service of the stub: the call's args in, (values, result) out.
Service = Callable[[dict[str, Any]], tuple[Any, bool]]


class StubRosbridge:
    """Answers rosapi ``topic_type`` with ``topic_type`` and each of ``services``; records ops
    and handshakes; ``refuse_cbor``: a warning status for a CBOR subscription."""

    def __init__(self, topic_type: str = "", refuse_cbor: bool = False) -> None:
        self.topic_type = topic_type
        self.refuse_cbor = refuse_cbor
        self.services: dict[str, Service] = {}
        self.ops: list[dict[str, Any]] = []
        # The Authorization header of each handshake (None when there was none).
        self.authorizations: list[str | None] = []
        self.connection: ServerConnection | None = None
        self.server: Server | None = None

    @property
    def url(self) -> str:
        assert self.server is not None
        port = next(iter(self.server.sockets)).getsockname()[1]
        return f"ws://127.0.0.1:{port}"

    @property
    def subscribes(self) -> list[dict[str, Any]]:
        return self.of("subscribe")

    def of(self, op: str) -> list[dict[str, Any]]:
        """The ops of one kind received so far, in order."""
        return [message for message in self.ops if message["op"] == op]

    async def _serve(self, connection: ServerConnection) -> None:
        self.connection = connection
        assert connection.request is not None
        self.authorizations.append(connection.request.headers.get("Authorization"))
        async for text in connection:
            message = json.loads(text)
            self.ops.append(message)
            if message["op"] == "call_service":
                await self._answer(connection, message)
            elif message["op"] == "subscribe":
                if self.refuse_cbor and message.get("compression") == "cbor":
                    warning = {
                        "op": "status",
                        "level": "warning",
                        "id": message["id"],
                        "msg": "unknown compression cbor",
                    }
                    await connection.send(json.dumps(warning))

    async def _answer(self, connection: ServerConnection, message: dict[str, Any]) -> None:
        service = message["service"]
        if service == "/rosapi/topic_type":
            values, result = {"type": self.topic_type}, True
        elif service in self.services:
            values, result = self.services[service](message["args"])
        else:
            return  # a service nobody offers: no answer at all
        answer = {"op": "service_response", "id": message["id"], "values": values}
        await connection.send(json.dumps({**answer, "service": service, "result": result}))

    async def send(self, frame: str | bytes) -> None:
        assert self.connection is not None
        await self.connection.send(frame)

    async def publish(self, topic: str, msg: dict[str, Any], binary: bool = True) -> None:
        op = {"op": "publish", "topic": topic}
        if binary:
            await self.send(cbor2.dumps({**op, "msg": msg}))
        else:
            await self.send(jsonedge.dumps({**op, "msg": msg}))  # bytes in base64

    async def drop(self) -> None:
        """End the current connection, as a restarted rosbridge would."""
        assert self.connection is not None
        await self.connection.close()


@contextlib.asynccontextmanager
async def running(rosbridge: StubRosbridge) -> AsyncIterator[StubRosbridge]:
    """``rosbridge`` listening on a free loopback port."""
    async with serve(rosbridge._serve, "127.0.0.1", 0, max_size=None) as server:
        rosbridge.server = server
        yield rosbridge
