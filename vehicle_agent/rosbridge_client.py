"""A small rosbridge v2 client of the agent's own, for the camera's stream (docs/camera.md).

roslibpy (the turtle's client) asks only for ``png`` or no compression, so every image would
reach it as JSON with its bytes in base64. This client subscribes with ``compression: "cbor"``:
a rosbridge_server that offers CBOR then sends each message as a binary WebSocket frame, CBOR
encoded, the image's ``data`` a byte string. A server that does not keeps sending JSON text
frames, which this client reads just as well, so nothing needs to know in advance which it gets.

:func:`read_frame` is the sans-I/O part: one frame in (text or binary), one typed item out, a
frame that is no rosbridge message included (:class:`Unreadable`). :class:`RosbridgeClient` moves
the frames (the ``websockets`` library), with the same bearer token on the handshake as the
turtle's client sends to the server's own ``/rosbridge`` and the same TLS trust as the agent's
other connections.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import ssl
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Annotated, Any, Final, Literal

import cbor2
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StrictStr,
    TypeAdapter,
    ValidationError,
)
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI

from app.protocol import jsonedge
from app.protocol.errors import describe
from app.protocol.urls import untrusted_hint

log = logging.getLogger(__name__)

CONNECT_TIMEOUT_S: Final = 5.0
# The largest frame read: a 1920x1080 rgb8 Image in base64 JSON is 8.3 MB.
MAX_FRAME_BYTES: Final = 16 * 2**20
# rosbridge's subscription compressions this client asks for: CBOR, or none (JSON).
Compression = Literal["cbor", "none"]
CBOR: Final[Compression] = "cbor"
NONE: Final[Compression] = "none"


class RosbridgeError(RuntimeError):
    """The rosbridge could not be reached or refused the connection; the message says why."""


# -- what arrives --------------------------------------------------------------------------


class _Op(BaseModel):
    # rosbridge adds fields over the versions (fragment ids, ...): ignored.
    model_config = ConfigDict(extra="ignore", frozen=True)

    id: StrictStr | int | None = None


class PublishOp(_Op):
    """``publish``: a message on a subscribed topic (``msg`` is read by the subscriber)."""

    op: Literal["publish"]
    topic: StrictStr
    msg: dict[str, Any]


class StatusOp(_Op):
    """``status``: the server's word on one of our requests (``id``) or on the connection."""

    op: Literal["status"]
    level: StrictStr = "info"
    msg: StrictStr = ""


class ServiceResponseOp(_Op):
    """``service_response``: the answer to a ``call_service`` of ours."""

    op: Literal["service_response"]
    service: StrictStr = ""
    values: Any = None
    result: StrictBool = True


_Incoming = Annotated[PublishOp | StatusOp | ServiceResponseOp, Field(discriminator="op")]
_incoming: TypeAdapter[PublishOp | StatusOp | ServiceResponseOp] = TypeAdapter(_Incoming)
_READ_OPS: Final = frozenset({"publish", "status", "service_response"})


@dataclass(frozen=True)
class Publication:
    """A message on ``topic``, received at ``at`` (monotonic s) = ``wall`` (Unix s); ``binary``
    when it came as CBOR."""

    topic: str
    msg: dict[str, Any]
    binary: bool
    at: float
    wall: float


@dataclass(frozen=True)
class Unreadable:
    """A frame that is no rosbridge message this client reads, and why."""

    reason: str
    binary: bool


@dataclass(frozen=True)
class Ignored:
    """A rosbridge op this client has no use for (``png`` fragments, ...)."""

    op: str


Incoming = Publication | StatusOp | ServiceResponseOp | Unreadable | Ignored


def read_frame(frame: str | bytes, at: float, wall: float) -> Incoming:
    """One WebSocket frame as a typed item: a text frame is JSON, a binary one CBOR."""
    binary = isinstance(frame, bytes)
    try:
        message = cbor2.loads(frame) if isinstance(frame, bytes) else jsonedge.loads(frame)
    except cbor2.CBORDecodeError as exc:
        return Unreadable(f"a binary frame that is not CBOR: {exc}", binary)
    except jsonedge.JsonEdgeError as exc:
        return Unreadable(str(exc), binary)
    if not isinstance(message, dict):
        return Unreadable("a rosbridge message must be an object", binary)
    op = message.get("op")
    if not isinstance(op, str):
        return Unreadable("message has no string 'op' field", binary)
    if op not in _READ_OPS:
        return Ignored(op)
    try:
        item = _incoming.validate_python(message)
    except ValidationError as exc:
        return Unreadable(f"{op}: {describe(exc, skip=1)}", binary)
    if isinstance(item, PublishOp):
        return Publication(item.topic, item.msg, binary, at, wall)
    return item


# -- the connection ------------------------------------------------------------------------


class RosbridgeClient:
    """One connection to a rosbridge v2 server (``ws://`` or ``wss://``)."""

    def __init__(self, url: str, token: str | None = None, tls: ssl.SSLContext | None = None):
        if not url.startswith(("ws://", "wss://")):
            raise RosbridgeError(f"rosbridge URL must start with ws:// or wss://, not {url!r}")
        self.url = url
        self.token = token
        # Only for wss://; None there means the system's trusted CAs.
        self.tls = tls if url.startswith("wss:") else None
        self._ws: ClientConnection | None = None
        self._ids = itertools.count(1)

    async def connect(self) -> None:
        """Open the connection; :class:`RosbridgeError` says why it could not."""
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else None
        try:
            self._ws = await connect(
                self.url,
                additional_headers=headers,
                ssl=self.tls,
                open_timeout=CONNECT_TIMEOUT_S,
                max_size=MAX_FRAME_BYTES,
                # Frames are read as they come and only the newest kept, so the library's own
                # queue need not hold more than a couple.
                max_queue=4,
                compression=None,
            )
        except (OSError, InvalidURI, InvalidHandshake, TimeoutError) as exc:
            raise RosbridgeError(
                f"cannot connect to rosbridge at {self.url}: {exc or type(exc).__name__}"
                f"{untrusted_hint(exc)}"
            ) from exc

    def new_id(self, kind: str) -> str:
        """A fresh request id, ``kind:N``."""
        return f"{kind}:{next(self._ids)}"

    async def send(self, message: dict[str, Any]) -> bool:
        """Send one op as JSON; False when the connection is closed (the reader notices)."""
        if self._ws is None:
            return False
        try:
            await self._ws.send(jsonedge.dumps(message))
        except ConnectionClosed:
            return False
        return True

    async def call(self, service: str, args: dict[str, Any], timeout: float) -> Any | None:
        """Call ``service`` and wait for its values; None when it failed or did not answer in
        ``timeout`` s. Frames that arrive meanwhile and are not the answer are dropped: call
        before subscribing."""
        request_id = self.new_id("call")
        sent = await self.send(
            {"op": "call_service", "id": request_id, "service": service, "args": args}
        )
        if not sent:
            return None
        try:
            async with asyncio.timeout(timeout):
                while True:
                    item = await self._next()
                    if isinstance(item, ServiceResponseOp) and item.id == request_id:
                        break
        except TimeoutError:
            log.info("%s: no answer within %g s", service, timeout)
            return None
        except ConnectionClosed:
            return None
        if not item.result:
            log.info("%s failed: %s", service, item.values)
            return None
        return item.values

    async def incoming(self) -> AsyncIterator[Incoming]:
        """The server's frames as typed items, until the connection closes."""
        try:
            while True:
                yield await self._next()
        except ConnectionClosed as exc:
            log.debug("rosbridge connection to %s closed: %s", self.url, exc)

    async def _next(self) -> Incoming:
        """The next frame; ConnectionClosed once the connection is (or was never) open."""
        if self._ws is None:
            raise ConnectionClosed(None, None)
        frame = await self._ws.recv()
        return read_frame(frame, time.monotonic(), time.time())

    async def close(self) -> None:
        """Close the connection."""
        ws, self._ws = self._ws, None
        if ws is not None:
            await ws.close()
