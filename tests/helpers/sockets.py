"""Socket helpers for tests that talk to the real server: JSON over WebSockets, a client that
never reads, and a log handler that sees what uvicorn logs."""

from __future__ import annotations

import asyncio
import json
import logging
import socket
import traceback
from typing import Any
from urllib.parse import urlsplit

from websockets.asyncio.client import ClientConnection
from websockets.client import ClientProtocol
from websockets.http11 import Response
from websockets.uri import parse_uri

from app.server.serve import RunningServer

TIMEOUT_S = 10


class Records(logging.Handler):
    """Every record the server logs (uvicorn's loggers do not propagate to the root)."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def tracebacks(self) -> list[str]:
        """Each logged exception: its message and the last lines of its traceback."""
        return [
            r.getMessage() + "\n" + "".join(traceback.format_exception(*r.exc_info))[-1500:]
            for r in self.records
            if r.exc_info
        ]


def rosbridge_url(server: RunningServer) -> str:
    return server.url.replace("http", "ws", 1) + "/rosbridge"


async def recv(ws: ClientConnection) -> dict[str, Any]:
    message: dict[str, Any] = json.loads(await asyncio.wait_for(ws.recv(), TIMEOUT_S))
    return message


async def login(ws: ClientConnection, name: str, role: str) -> None:
    await ws.send(json.dumps({"type": "login", "name": name, "role": role}))
    assert (await recv(ws))["success"] is True


class StuckClient:
    """A WebSocket client that sends but never reads a byte (websockets' sans-I/O protocol over
    a blocking socket with a small receive buffer), as a hung or malicious peer would."""

    def __init__(self, url: str) -> None:
        parts = urlsplit(url)
        self.sock = socket.socket()
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        self.sock.settimeout(TIMEOUT_S)
        self.sock.connect((parts.hostname or "127.0.0.1", parts.port or 80))
        self.protocol = ClientProtocol(parse_uri(url))
        self.protocol.send_request(self.protocol.connect())
        self._flush()
        while self.protocol.handshake_exc is None and not isinstance(
            next(iter(self.protocol.events_received()), None), Response
        ):
            self.protocol.receive_data(self.sock.recv(4096))
        self.sock.settimeout(0.5)

    def send(self, text: str) -> bool:
        """Send one text frame; False once the server has stopped reading from us."""
        self.protocol.send_text(text.encode())
        try:
            self._flush()
        except OSError:  # send timed out or the connection was reset: we were dropped
            return False
        return True

    def _flush(self) -> None:
        for data in self.protocol.data_to_send():
            self.sock.sendall(data)

    def close(self) -> None:
        self.sock.close()
