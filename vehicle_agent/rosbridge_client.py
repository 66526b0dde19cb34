"""The agent's one rosbridge v2 client: the robot's topics and its camera over one connection.

It covers what the agent needs of a rosbridge: ``advertise`` and ``publish`` (velocity commands),
``subscribe`` (the robot's pose; its camera in CBOR, :doc:`docs/camera.md`), ``call_service``
(rosapi's ``topic_type``, the spawn step's ``teleport_absolute``), the bearer token on the
handshake and the ``auth`` op that proves a renewed one, and reconnection with backoff
(:class:`app.supervise.Backoff`) that advertises and subscribes again what it had.

A subscription asks for ``compression: "cbor"`` where it wants binary frames: a rosbridge_server
that offers CBOR then sends each of its messages as a binary WebSocket frame, CBOR encoded, an
image's ``data`` a byte string. A server that does not keeps sending JSON text frames, which this
client reads just as well, so nothing needs to know in advance which it gets.

:func:`read_frame` is the sans-I/O part: one frame in (text or binary), one typed item out, a
frame that is no rosbridge message included (:class:`Unreadable`). :class:`RosbridgeClient` moves
the frames (the ``websockets`` library) and hands each item to whoever asked for it.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import ssl
import time
from collections.abc import Callable
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
from app.protocol.ros import DETECT_TIMEOUT_S
from app.protocol.urls import untrusted_hint
from app.supervise import Backoff

log = logging.getLogger(__name__)

CONNECT_TIMEOUT_S: Final = 5.0
# The largest frame read: a 1920x1080 rgb8 Image in base64 JSON is 8.3 MB.
MAX_FRAME_BYTES: Final = 16 * 2**20
# rosbridge's subscription compressions this client asks for: CBOR, or none (JSON).
Compression = Literal["cbor", "none"]
CBOR: Final[Compression] = "cbor"
NONE: Final[Compression] = "none"
# Ops waiting for the writer; beyond this a send is dropped (a rosbridge that reads nothing).
OUTBOX: Final = 256


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

PublicationCallback = Callable[[Publication], None]
StatusCallback = Callable[[StatusOp], None]


class CallFailed(RosbridgeError):
    """A service call failed, went unanswered, or had no connection to go out on."""


@dataclass(eq=False)
class Subscription:
    """One of the client's subscriptions, asked for again on every connection. After changing
    ``compression``, :meth:`RosbridgeClient.resubscribe` tells the server."""

    id: str
    topic: str
    type: str
    on_message: PublicationCallback
    compression: Compression = NONE
    queue_length: int | None = None
    # The server's word on this subscription (a compression it does not know, ...).
    on_status: StatusCallback | None = None

    def op(self) -> dict[str, Any]:
        """The ``subscribe`` op that asks for it."""
        message: dict[str, Any] = {
            "op": "subscribe",
            "id": self.id,
            "topic": self.topic,
            "type": self.type,
            "compression": self.compression,
        }
        if self.queue_length is not None:
            message["queue_length"] = self.queue_length
        return message


class RosbridgeClient:
    """One connection to a rosbridge v2 server (``ws://`` or ``wss://``), kept open.

    ``token`` goes as a bearer header on every handshake (only the server's own ``/rosbridge``
    is given one); ``tls`` is the trust for ``wss://`` (None: the system's CAs). Once
    :meth:`connect` succeeds, a lost connection is opened again with backoff, its advertisements
    and subscriptions asked for again; what is sent while it is down is dropped (a velocity
    command must not arrive late), and a call pending when it drops fails.
    """

    def __init__(self, url: str, token: str | None = None, tls: ssl.SSLContext | None = None):
        if not url.startswith(("ws://", "wss://")):
            raise RosbridgeError(f"rosbridge URL must start with ws:// or wss://, not {url!r}")
        self.url = url
        self.token = token
        # wss:// only: the system's trusted CAs unless told otherwise.
        self.tls = (tls or ssl.create_default_context()) if url.startswith("wss:") else None
        # Connections opened; frames that were no rosbridge message; sends dropped (outbox full).
        self.opened = 0
        self.unreadable = 0
        self.dropped = 0
        self._ws: ClientConnection | None = None
        self._outbox: asyncio.Queue[str] | None = None
        self._writer: asyncio.Task[None] | None = None
        self._advertised: dict[str, str] = {}
        self._subscriptions: dict[str, Subscription] = {}
        self._calls: dict[str, asyncio.Future[ServiceResponseOp]] = {}
        self._task: asyncio.Task[None] | None = None
        self._connecting = asyncio.Lock()
        self._ids = itertools.count(1)
        self._said: set[str] = set()

    @property
    def connected(self) -> bool:
        """Whether the connection is open now."""
        return self._ws is not None

    async def connect(self) -> None:
        """Open the connection and keep it open until :meth:`close`; a second call returns at
        once. :class:`RosbridgeError` says why the first opening failed."""
        async with self._connecting:
            if self._task is not None:
                return
            ws = await self._open()
            self._attach(ws)
            self._task = asyncio.create_task(self._run(ws), name=f"rosbridge {self.url}")

    async def _open(self) -> ClientConnection:
        headers = {"Authorization": f"Bearer {self.token}"} if self.token else None
        try:
            return await connect(
                self.url,
                additional_headers=headers,
                ssl=self.tls,
                open_timeout=CONNECT_TIMEOUT_S,
                max_size=MAX_FRAME_BYTES,
                # Frames are handed on as they come, so the library's own queue stays short.
                max_queue=16,
                compression=None,
            )
        except ConnectionRefusedError as exc:
            raise RosbridgeError(
                f"cannot connect to rosbridge at {self.url}: connection refused (is rosbridge "
                "running on that port?)"
            ) from exc
        except (OSError, InvalidURI, InvalidHandshake, TimeoutError) as exc:
            raise RosbridgeError(
                f"cannot connect to rosbridge at {self.url}: {exc or type(exc).__name__}"
                f"{untrusted_hint(exc)}"
            ) from exc

    def _attach(self, ws: ClientConnection) -> None:
        """Make ``ws`` the connection, with a writer: ask again for what the last one had."""
        outbox: asyncio.Queue[str] = asyncio.Queue(OUTBOX)
        self._ws, self._outbox = ws, outbox
        self.opened += 1
        # Statuses about our own requests (a refused compression) come only after set_level.
        self._send({"op": "set_level", "level": "warning"})
        for topic, kind in self._advertised.items():
            self._send(_advertise(topic, kind))
        for subscription in self._subscriptions.values():
            self._send(subscription.op())
        self._writer = asyncio.create_task(_write(ws, outbox), name=f"rosbridge writer {self.url}")

    async def _detach(self, ws: ClientConnection) -> None:
        """``ws`` is done with: stop its writer, fail the calls waiting on it, close it."""
        writer = self._writer
        self._ws = self._outbox = self._writer = None
        if writer is not None:
            writer.cancel()
            await asyncio.gather(writer, return_exceptions=True)
        for call in self._calls.values():
            if not call.done():
                call.set_exception(CallFailed(f"rosbridge connection to {self.url} lost"))
        await ws.close()

    async def _run(self, ws: ClientConnection) -> None:
        """Read the connection; when it drops, open another with backoff, until cancelled."""
        backoff = Backoff()
        while True:
            if await self._read(ws):
                backoff.reset()
            log.warning("rosbridge connection to %s lost; reconnecting", self.url)
            while True:
                await asyncio.sleep(backoff.next())
                try:
                    ws = await self._open()
                except RosbridgeError as exc:
                    self._say_once("reconnect", logging.WARNING, "%s; retrying", exc)
                    continue
                break
            self._said.discard("reconnect")
            log.info("reconnected to rosbridge at %s", self.url)
            self._attach(ws)

    async def _read(self, ws: ClientConnection) -> bool:
        """Hand on every frame until the connection closes; whether any came."""
        heard = False
        try:
            async for frame in ws:
                heard = True
                self._dispatch(read_frame(frame, time.monotonic(), time.time()))
        except ConnectionClosed as exc:
            log.debug("rosbridge connection to %s closed: %s", self.url, exc)
        finally:
            await self._detach(ws)
        return heard

    def _dispatch(self, item: Incoming) -> None:
        match item:
            case Publication(topic=topic):
                for subscription in list(self._subscriptions.values()):
                    if subscription.topic == topic:
                        subscription.on_message(item)
            case ServiceResponseOp(id=str(request)) if request in self._calls:
                call = self._calls[request]
                if not call.done():
                    call.set_result(item)
            case StatusOp(id=str(request)) if request in self._subscriptions:
                on_status = self._subscriptions[request].on_status
                if on_status is not None:
                    on_status(item)
            case StatusOp(level="warning" | "error"):
                self._say_once(
                    f"status:{item.msg}",
                    logging.WARNING,
                    "rosbridge at %s says %s",
                    self.url,
                    item.msg,
                )
            case Unreadable(reason=reason):
                self.unreadable += 1
                self._say_once(
                    "unreadable",
                    logging.WARNING,
                    "rosbridge at %s: skipped an unreadable frame: %s",
                    self.url,
                    reason,
                )
            case _:
                log.debug("rosbridge at %s: ignoring %s", self.url, item)

    def _send(self, message: dict[str, Any]) -> bool:
        """Queue one op for the writer; False while there is no connection or no room."""
        outbox = self._outbox
        if outbox is None:
            return False
        try:
            outbox.put_nowait(jsonedge.dumps(message))
        except asyncio.QueueFull:
            self.dropped += 1
            self._say_once(
                "full", logging.WARNING, "rosbridge at %s takes nothing we send: dropping", self.url
            )
            return False
        return True

    def _new_id(self, kind: str) -> str:
        return f"{kind}:{next(self._ids)}"

    # -- what the robot link and the camera ask for -------------------------------------

    def advertise(self, topic: str, kind: str) -> None:
        """Advertise ``topic`` as ``kind``, now and on every later connection."""
        self._advertised[topic] = kind
        self._send(_advertise(topic, kind))

    def unadvertise(self, topic: str) -> None:
        """Stop advertising ``topic``."""
        if self._advertised.pop(topic, None) is not None:
            self._send({"op": "unadvertise", "id": f"advertise:{topic}", "topic": topic})

    def publish(self, topic: str, msg: dict[str, Any]) -> bool:
        """Publish ``msg`` on an advertised ``topic``; False when it could not go out now."""
        return self._send({"op": "publish", "topic": topic, "msg": msg})

    def subscribe(
        self,
        topic: str,
        kind: str,
        on_message: PublicationCallback,
        *,
        compression: Compression = NONE,
        queue_length: int | None = None,
        on_status: StatusCallback | None = None,
    ) -> Subscription:
        """Subscribe to ``topic`` (of type ``kind``): ``on_message`` gets each message, on the
        event loop, now and after every reconnection."""
        subscription = Subscription(
            self._new_id(f"subscribe:{topic}"),
            topic,
            kind,
            on_message,
            compression,
            queue_length,
            on_status,
        )
        self._subscriptions[subscription.id] = subscription
        self._send(subscription.op())
        return subscription

    def resubscribe(self, subscription: Subscription) -> None:
        """Ask again for ``subscription`` as it is now (its compression changed)."""
        self._send(subscription.op())

    def unsubscribe(self, subscription: Subscription) -> None:
        """End ``subscription``."""
        if self._subscriptions.pop(subscription.id, None) is not None:
            self._send({"op": "unsubscribe", "id": subscription.id, "topic": subscription.topic})

    async def call(self, service: str, args: dict[str, Any], timeout: float) -> Any:
        """Call ``service`` and return its values; :class:`CallFailed` when it failed, did not
        answer within ``timeout`` s, or the connection was down or dropped."""
        request = self._new_id(f"call:{service}")
        answer: asyncio.Future[ServiceResponseOp] = asyncio.get_running_loop().create_future()
        self._calls[request] = answer
        try:
            message = {"op": "call_service", "id": request, "service": service, "args": args}
            if not self._send(message):
                raise CallFailed(f"{service}: not connected to rosbridge at {self.url}")
            try:
                async with asyncio.timeout(timeout):
                    reply = await answer
            except TimeoutError:
                raise CallFailed(f"{service}: no answer within {timeout:g} s") from None
        finally:
            del self._calls[request]
        if not reply.result:
            raise CallFailed(f"{service} failed: {reply.values}")
        return reply.values

    async def topic_type(self, topic: str) -> str | None:
        """rosapi's ``topic_type`` of ``topic``; None when rosapi is missing, silent or does not
        know it (within :data:`~app.protocol.ros.DETECT_TIMEOUT_S`)."""
        try:
            reply = await self.call("/rosapi/topic_type", {"topic": topic}, DETECT_TIMEOUT_S)
        except CallFailed as exc:
            log.info("rosapi topic_type %s: %s", topic, exc)
            return None
        kind = reply.get("type") if isinstance(reply, dict) else None
        return kind if isinstance(kind, str) and kind else None

    def renew(self, token: str) -> None:
        """The session's token was renewed: prove it with the ``auth`` op now, and send it on
        the next handshake (only if this rosbridge was given a token at all)."""
        if self.token is None:
            return
        self.token = token
        self._send({"op": "auth", "token": token})

    async def close(self) -> None:
        """Close the connection and stop reconnecting."""
        task, self._task = self._task, None
        if task is None:
            return
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        if self._ws is not None:  # cancelled before it began to read
            await self._detach(self._ws)

    def _say_once(self, key: str, level: int, message: str, *args: object) -> None:
        if key not in self._said:
            self._said.add(key)
            log.log(level, message, *args)


def _advertise(topic: str, kind: str) -> dict[str, Any]:
    return {"op": "advertise", "id": f"advertise:{topic}", "topic": topic, "type": kind}


async def _write(ws: ClientConnection, outbox: asyncio.Queue[str]) -> None:
    """Send the outbox's ops in order until the connection closes (its reader then notices)."""
    with contextlib.suppress(ConnectionClosed):
        while True:
            await ws.send(await outbox.get())
