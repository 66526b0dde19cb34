"""The one WebSocket adapter behind ``/ws`` and ``/rosbridge``: one policy for both sockets.

The rules live in sans-I/O cores (the signaling hub, the rosbridge session); this module only
moves frames between a socket and a core, the same way for both:

* **Size.** uvicorn refuses a frame larger than ``Settings.max_message_bytes`` before buffering
  it (``ws_max_size``, set in :mod:`app.server.serve`) and closes with 1009 "frame exceeds limit
  of N bytes"; a text frame that still arrives over the limit (an app served some other way) is
  refused here with an error reply.
* **Outbox.** Each connection has an :class:`Outbox` bounded in messages and bytes, drained by
  its own writer task, so a slow peer never holds up the others. A peer that leaves more than
  that unread is closed with 1013. Messages that newer ones supersede (rosbridge publications)
  are not queued at all: the writer pulls them from the core when it has sent everything else,
  so a peer that does not read is given none and costs nothing. Each route keeps its
  connections' outboxes in an :class:`Outboxes`, which also caps how many connections it
  accepts (1013 beyond that).
* **JSON.** Replies are written with :func:`app.protocol.jsonedge.dumps`: never NaN or Infinity.
  Incoming text is parsed by the cores with :func:`app.protocol.jsonedge.loads`.
* **Login.** Until a connection has shown a token (a ``/ws`` login, a ``/rosbridge`` auth) it
  is *waiting*. It has :attr:`SocketPolicy.login_timeout_s` to show one, else it is closed with
  1008 (the same deadline on both routes). Waiting connections hold at most
  :attr:`SocketPolicy.max_waiting` of a route's places, and
  :attr:`SocketPolicy.max_waiting_per_address` per client address: a newcomer beyond either, or
  at a full route, takes the place of the oldest waiting one (closed with 1013). So sockets
  without a token can never keep out a peer that has one, nor the newcomer about to log in.
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Callable, Hashable, ItemsView
from dataclasses import dataclass
from typing import Any, Final, Generic, TypeVar

from fastapi import WebSocket
from starlette.websockets import WebSocketDisconnect, WebSocketDisconnected

from app.protocol import jsonedge
from app.protocol.close_codes import CloseCode
from app.server.config import Settings
from app.signaling.hub import Refusal

log = logging.getLogger(__name__)

# After the close is queued, the writer has this long to deliver what precedes it; a peer that
# does not read by then gets no more (its socket's own buffer is bounded by uvicorn).
CLOSE_GRACE_S: Final = 2.0


@dataclass(frozen=True)
class SocketPolicy:
    """The limits every WebSocket connection gets, from :class:`~app.server.config.Settings`."""

    max_message_bytes: int
    outbox_messages: int
    outbox_bytes: int
    login_timeout_s: float = 10.0
    max_waiting: int = 32
    max_waiting_per_address: int = 8

    @classmethod
    def from_settings(cls, settings: Settings) -> SocketPolicy:
        """The limits of ``settings``."""
        return cls(
            settings.max_message_bytes,
            settings.outbox_messages,
            settings.outbox_bytes,
            settings.login_timeout_s,
            settings.max_waiting_connections,
            settings.max_waiting_per_address,
        )


@dataclass(frozen=True)
class Shut:
    """The last item of an outbox: close the socket with this code and reason."""

    code: int
    reason: str


# A frame as sent: JSON text, or a binary frame (a rosbridge subscription in CBOR).
Frame = str | bytes
Pull = Callable[[], list[Frame]]


class Outbox:
    """Frames waiting for one peer, bounded in count and bytes; overflowing closes the peer
    (and calls ``on_slow_reader``, for the metrics).

    ``pull`` gives the frames a newer one supersedes (publications, encoded by the core that
    makes them): asked for only when every queued frame has been sent and :meth:`wake` has said
    there may be some.
    """

    def __init__(
        self,
        max_messages: int,
        max_bytes: int,
        on_slow_reader: Callable[[], None] | None = None,
        pull: Pull | None = None,
    ) -> None:
        self.max_messages = max_messages
        self.max_bytes = max_bytes
        self.on_slow_reader = on_slow_reader
        self._pull = pull
        self._frames: deque[Frame] = deque()
        self._bytes = 0
        self._shut: Shut | None = None
        self._ready = asyncio.Event()
        self.closing = asyncio.Event()

    @property
    def shut(self) -> Shut | None:
        """The close queued behind the frames, once there is one."""
        return self._shut

    def __len__(self) -> int:
        return len(self._frames)

    def send(self, message: dict[str, Any]) -> None:
        """Queue a message; if the peer has left too much unread it is closed instead."""
        frame = self._encode(message)
        if frame is None or self._shut is not None:
            return
        if not self._fits(frame):
            unread = len(self._frames)
            log.warning("closing a slow reader: %d messages (%d bytes) unread", unread, self._bytes)
            if self.on_slow_reader is not None:
                self.on_slow_reader()
            self._frames.clear()
            self._bytes = 0
            self.close(CloseCode.TRY_AGAIN_LATER, f"too slow: {unread} messages left unread")
            return
        self._push(frame)

    def wake(self) -> None:
        """There may be messages to pull: the writer asks for them once it is free."""
        if self._pull is not None:
            self._ready.set()

    def close(self, code: int, reason: str) -> None:
        """Close the peer once the frames queued so far are sent; nothing is queued after it."""
        if self._shut is None:
            self._shut = Shut(code, reason)
            self._ready.set()
            self.closing.set()

    async def get(self) -> Frame | Shut:
        """The next frame, or the close once every frame before it has been taken."""
        while not self._frames:
            if self._shut is not None:
                return self._shut
            if self._pull is not None and self._pulled():
                break
            self._ready.clear()
            await self._ready.wait()
        frame = self._frames.popleft()
        self._bytes -= len(frame)
        return frame

    def _pulled(self) -> bool:
        """Queue what ``pull`` gives, as far as it fits; True when anything was queued."""
        assert self._pull is not None
        for frame in self._pull():
            if self._fits(frame):
                self._push(frame)
        return bool(self._frames)

    def _fits(self, frame: Frame) -> bool:
        return len(self._frames) < self.max_messages and self._bytes + len(frame) <= self.max_bytes

    def _push(self, frame: Frame) -> None:
        self._frames.append(frame)
        self._bytes += len(frame)
        self._ready.set()

    @staticmethod
    def _encode(message: dict[str, Any]) -> str | None:
        try:
            return jsonedge.dumps(message)
        except ValueError as exc:  # NaN or Infinity: a bug upstream, never sent to a browser
            log.error("not sending a %r message: %s", message.get("type", message.get("op")), exc)
            return None


K = TypeVar("K", bound=Hashable)


# Why a waiting connection loses its place to a newcomer.
MAKE_WAY = "too many connections waiting to log in"


class Outboxes(Generic[K]):
    """The outbox of each open connection of one route, keyed by the core's handle for it.

    At most ``limit`` connections at once, each outbox bounded by ``policy``, and of them at
    most the policy's budgets *waiting* (not yet shown a token; see the module's docstring).
    ``refused`` is told of each connection refused at the limit or made to make way for a
    newcomer (``caps``) and each slow reader closed.
    """

    def __init__(self, policy: SocketPolicy, limit: int) -> None:
        self.policy = policy
        self.limit = limit
        self.refused: Callable[[Refusal], None] | None = None
        self._by_key: dict[K, Outbox] = {}
        # The waiting connections, oldest first, with their client's address.
        self._waiting: dict[K, str] = {}

    def __len__(self) -> int:
        return len(self._by_key)

    @property
    def waiting(self) -> int:
        """How many connections have not shown a token yet."""
        return len(self._waiting)

    @property
    def full(self) -> bool:
        """True when no more connections are accepted: every place is taken, none by a
        connection that is still waiting (those make way)."""
        return self._live() >= self.limit and not self._waiting

    def open(self, key: K, address: str, pull: Pull | None = None, waiting: bool = True) -> Outbox:
        """A new connection from ``address``: its outbox (``pull``: see :class:`Outbox`);
        ``waiting`` until :meth:`authenticated`. Makes way for it first (see the module)."""
        if waiting:
            self._make_way(address)
        elif self._live() >= self.limit and self._waiting:
            self._evict(next(iter(self._waiting)))
        outbox = Outbox(
            self.policy.outbox_messages, self.policy.outbox_bytes, self._slow_reader, pull
        )
        self._by_key[key] = outbox
        if waiting:
            self._waiting[key] = address
        return outbox

    def authenticated(self, key: K) -> None:
        """The connection has shown a token: it no longer counts as waiting."""
        self._waiting.pop(key, None)

    def _make_way(self, address: str) -> None:
        """Close the oldest waiting connections over a budget, so a newcomer fits."""
        same = [key for key, where in self._waiting.items() if where == address]
        if len(same) >= self.policy.max_waiting_per_address:
            self._evict(same[0])
        if len(self._waiting) >= self.policy.max_waiting:
            self._evict(next(iter(self._waiting)))
        if self._live() >= self.limit and self._waiting:
            self._evict(next(iter(self._waiting)))

    def _evict(self, key: K) -> None:
        del self._waiting[key]
        self._by_key[key].close(CloseCode.TRY_AGAIN_LATER, MAKE_WAY)
        if self.refused is not None:
            self.refused("caps")

    def _live(self) -> int:
        """Connections not yet closing: those closed are on their way out."""
        return sum(1 for outbox in self._by_key.values() if outbox.shut is None)

    def _slow_reader(self) -> None:
        if self.refused is not None:
            self.refused("slow_reader")

    def forget(self, key: K) -> None:
        """The connection is gone: so is its outbox."""
        self._by_key.pop(key, None)
        self._waiting.pop(key, None)

    def get(self, key: K) -> Outbox | None:
        """The connection's outbox; None once it is forgotten."""
        return self._by_key.get(key)

    def items(self) -> ItemsView[K, Outbox]:
        """Each open connection with its outbox."""
        return self._by_key.items()


def client_address(websocket: WebSocket) -> str:
    """The address the connection comes from (its waiting budget is counted per address)."""
    return websocket.client.host if websocket.client is not None else "unknown"


Deadline = tuple[float, Callable[[], bool], str]


def login_deadline(policy: SocketPolicy, met: Callable[[], bool], what: str) -> Deadline:
    """The deadline of :func:`serve` for showing a token (``what``: the route's word for it)."""
    seconds = policy.login_timeout_s
    return seconds, met, f"no {what} within {seconds:g} s"


async def refuse_if_full(websocket: WebSocket, outboxes: Outboxes[Any], what: str) -> bool:
    """Close an accepted socket with 1013 when ``outboxes`` is full: its limit of ``what``.

    True when the socket was refused; the route then returns without serving it.
    """
    if not outboxes.full:
        return False
    reason = f"server full: {outboxes.limit} {what}"
    if outboxes.refused is not None:
        outboxes.refused("caps")
    log.warning("refusing a connection: %s", reason)
    await websocket.close(CloseCode.TRY_AGAIN_LATER, reason)
    return True


async def serve(
    websocket: WebSocket,
    outbox: Outbox,
    on_text: Callable[[str], None],
    on_binary: Callable[[bytes], None],
    *,
    name: str,
    deadline: Deadline | None = None,
) -> None:
    """Pump one accepted socket until it closes or its outbox is closed.

    Each text frame goes to ``on_text`` and each binary frame to ``on_binary``; they answer by
    queueing on ``outbox``. ``deadline`` is ``(seconds, met, reason)``: unless ``met()`` is
    true that long after the start, the connection is closed with 1008 and ``reason``.
    """
    loop = asyncio.get_running_loop()
    timer = None
    if deadline is not None:
        seconds, met, reason = deadline

        def check() -> None:
            if not met():
                log.info("closing %s: %s", name, reason)
                outbox.close(CloseCode.POLICY_VIOLATION, reason)

        timer = loop.call_later(seconds, check)
    reader = asyncio.create_task(
        _read(websocket, outbox, on_text, on_binary), name=f"{name}-reader"
    )
    writer = asyncio.create_task(_write(websocket, outbox), name=f"{name}-writer")
    closing = asyncio.create_task(outbox.closing.wait(), name=f"{name}-closing")
    tasks = (reader, writer, closing)
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        if outbox.shut is not None and not writer.done():
            # Deliver what precedes the close, then the close; a peer that reads nothing
            # would keep the writer waiting on a full socket buffer forever.
            await asyncio.wait([writer], timeout=CLOSE_GRACE_S)
    finally:
        if timer is not None:
            timer.cancel()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        for task in (reader, writer):
            if not task.cancelled() and (error := task.exception()) is not None:
                log.error("%s died", task.get_name(), exc_info=error)


async def _read(
    websocket: WebSocket,
    outbox: Outbox,
    on_text: Callable[[str], None],
    on_binary: Callable[[bytes], None],
) -> None:
    while outbox.shut is None:
        frame = await websocket.receive()
        if frame["type"] == "websocket.disconnect":
            return
        text = frame.get("text")
        if text is not None:
            on_text(text)
        else:
            on_binary(frame.get("bytes") or b"")


async def _write(websocket: WebSocket, outbox: Outbox) -> None:
    try:
        while True:
            item = await outbox.get()
            if isinstance(item, Shut):
                await websocket.close(item.code, item.reason)
                return
            if isinstance(item, bytes):
                await websocket.send_bytes(item)
            else:
                await websocket.send_text(item)
    except (WebSocketDisconnect, WebSocketDisconnected):
        return
    except RuntimeError as exc:
        # uvicorn closed the socket itself (1007 invalid UTF-8, 1009 frame too big) while this
        # frame was on its way: the reader sees the disconnect; nothing is left to deliver.
        log.debug("not delivered, socket closed by the server: %s", exc)
        return
