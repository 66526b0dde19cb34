"""The Foxglove view on the network, behind a token: a TLS WebSocket front that checks each
viewer's room token and then carries the Foxglove protocol, untouched, to the SDK's server on a
loopback port (docs/foxglove.md, "Safety").

The SDK's server can serve TLS but checks no token, so with ``AUTOPILOT_SECRET`` set
``autopilot vehicle --foxglove HOST:PORT`` serves it on 127.0.0.1 (a port the system picks) and
puts this gate at ``HOST:PORT``:

- a viewer offers a token as the server's peers do, signed with the same secret
  (``autopilot token``): an ``Authorization: Bearer`` header, or ``wss://HOST:PORT/?token=T``
  for Foxglove, whose browser WebSocket cannot send a header. It must be a token of the
  vehicle's room; any of its roles will do (a viewer only reads: the server advertises no
  capability, so nothing from a viewer can move the robot);
- a refused viewer gets the WebSocket opened and closed at once with 1008 and the reason
  (:func:`admit`), which the client shows; it never reaches the SDK's server;
- an admitted one is joined to a connection of its own to the SDK's server, opened with the
  subprotocols it offered, so the SDK chooses (``foxglove.sdk.v1`` or
  ``foxglove.websocket.v1``) and the gate answers with the SDK's choice. Frames go both ways as
  they are. It is closed with 1008 "token expired" when its token expires, as the server's own
  sockets are;
- the gate runs on a thread and an event loop of its own, so neither a refusal nor the TLS and
  the copying of the camera's images take the agent's loop. A viewer that does not read holds
  up only its own pair of sockets: the gate stops reading the SDK's side, and the SDK drops the
  oldest of that viewer's queued messages (:data:`vehicle_agent.foxglove.BACKLOG`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import ssl
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidStatus
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

from app.protocol import tokens
from app.protocol.close_codes import CloseCode
from app.protocol.tokens import Claims, TokenError

log = logging.getLogger(__name__)

# The subprotocols of the Foxglove WebSocket protocol: the SDK's, and the one Foxglove's client
# library names (which the SDK's server also speaks).
SUBPROTOCOLS: Final = (Subprotocol("foxglove.sdk.v1"), Subprotocol("foxglove.websocket.v1"))
TOKEN_HINT: Final = (
    "send a token of this vehicle's room: wss://HOST:PORT/?token=T or Authorization: Bearer T"
)
EXPIRED: Final = "token expired"
# A close reason fits in a control frame: 125 bytes, two of them the code.
MAX_REASON_BYTES: Final = 123
# Messages held for a viewer from the SDK's side before the gate stops reading it (a slow
# viewer then falls behind in the SDK's backlog, where the oldest are dropped).
UPSTREAM_QUEUE: Final = 4
# A peer that does not answer a close (a viewer that does not read) is dropped this much later.
CLOSE_TIMEOUT_S: Final = 2.0
# A viewer's own messages (subscriptions) are small; an image goes only the other way.
VIEWER_MAX_MESSAGE_BYTES: Final = 64 * 1024


def admit(secret: str, room: str, token: str | None, now: float) -> Claims | str:
    """What ``token`` grants a viewer of ``room``'s vehicle, or why it is refused."""
    if token is None:
        return TOKEN_HINT
    try:
        return tokens.verify(secret, token, now=now, room=room)
    except TokenError as exc:
        return str(exc)


def close_reason(text: str) -> str:
    """``text`` cut to what a close frame carries (at a character boundary)."""
    return text.encode()[:MAX_REASON_BYTES].decode(errors="ignore")


def server_tls(certfile: Path, keyfile: Path) -> ssl.SSLContext:
    """A server context presenting ``certfile`` (a PEM chain) and ``keyfile``; OSError naming
    the file when they cannot be used."""
    context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
    try:
        context.load_cert_chain(certfile, keyfile)
    except (OSError, ssl.SSLError) as exc:
        raise OSError(f"cannot serve wss:// with {certfile} and {keyfile}: {exc}") from exc
    return context


Socket = ServerConnection | ClientConnection


@dataclass(frozen=True)
class _Admitted:
    claims: Claims
    upstream: ClientConnection


class FoxgloveGate:
    """A TLS WebSocket front at ``host:port`` that admits viewers of ``room`` with a token
    signed with ``secret`` and joins each to the Foxglove server at ``upstream`` (a ``ws://``
    URL on this machine), on a thread of its own until :meth:`close`. ``clock``: Unix seconds,
    for the tokens."""

    def __init__(
        self,
        host: str,
        port: int,
        upstream: str,
        tls: ssl.SSLContext,
        secret: str,
        room: str,
        clock: Callable[[], float] = time.time,
    ) -> None:
        """Start serving; OSError when ``host:port`` cannot be bound."""
        self.upstream = upstream
        self._tls = tls
        self._secret = secret
        self._room = room
        self._clock = clock
        self.refused = 0
        self.admitted = 0
        # What each connection's handshake decided, for its handler.
        self._decided: dict[ServerConnection, _Admitted | str] = {}
        self._loop = asyncio.new_event_loop()
        self._stop: asyncio.Event | None = None
        started: Future[int] = Future()
        self._thread = threading.Thread(
            target=self._run, args=(host, port, started), name="foxglove-gate", daemon=True
        )
        self._thread.start()
        self.port = started.result()

    def _run(self, host: str, port: int, started: Future[int]) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._serve(host, port, started))
        finally:
            self._loop.close()

    async def _serve(self, host: str, port: int, started: Future[int]) -> None:
        self._stop = asyncio.Event()
        try:
            server = await serve(
                self._handle,
                host,
                port,
                ssl=self._tls,
                process_request=self._check,
                select_subprotocol=self._subprotocol,
                compression=None,  # JPEG and protobuf: deflate would cost CPU for nothing
                max_size=VIEWER_MAX_MESSAGE_BYTES,
                close_timeout=CLOSE_TIMEOUT_S,
            )
        except OSError as exc:
            started.set_exception(OSError(f"cannot serve Foxglove on {host}:{port}: {exc}"))
            return
        started.set_result(_bound_port(server))
        async with server:
            await self._stop.wait()
            server.close(close_connections=True)

    async def _check(self, connection: ServerConnection, request: Request) -> Response | None:
        verdict = admit(
            self._secret, self._room, tokens.request_token(request.path, request.headers),
            self._clock(),
        )  # fmt: skip
        # A viewer that goes before its handler starts leaves nothing behind (no connection
        # open upstream).
        connection.connection_lost_waiter.add_done_callback(lambda _: self._forget(connection))
        if isinstance(verdict, str):
            # Opened, then closed with the reason: a client shows a close reason, and an HTTP
            # refusal's body it would not.
            self._decided[connection] = verdict
            return None
        offered = [p.strip() for v in request.headers.get_all("Sec-WebSocket-Protocol")
                   for p in v.split(",") if p.strip()]  # fmt: skip
        try:
            upstream = await connect(
                self.upstream,
                subprotocols=[Subprotocol(p) for p in offered],
                compression=None,
                max_size=None,
                max_queue=UPSTREAM_QUEUE,
                open_timeout=5,
                close_timeout=CLOSE_TIMEOUT_S,
            )
        except InvalidStatus as exc:  # the SDK's answer (a subprotocol it does not speak)
            status = exc.response.status_code
            return connection.respond(status, f"the vehicle's Foxglove server answered {status}\n")
        except (OSError, InvalidHandshake, TimeoutError) as exc:
            log.warning("Foxglove gate: cannot reach the vehicle's Foxglove server: %s", exc)
            return connection.respond(502, "the vehicle's Foxglove server is not answering\n")
        self._decided[connection] = _Admitted(verdict, upstream)
        return None

    def _forget(self, connection: ServerConnection) -> None:
        decided = self._decided.pop(connection, None)
        if isinstance(decided, _Admitted):
            decided.upstream.transport.abort()

    def _subprotocol(
        self, connection: ServerConnection, offered: Sequence[Subprotocol]
    ) -> Subprotocol | None:
        decided = self._decided.get(connection)
        if isinstance(decided, _Admitted):
            return decided.upstream.subprotocol
        # A refused viewer gets a subprotocol it offered, so that its client takes the handshake
        # and reads the close reason.
        return next((p for p in offered if p in SUBPROTOCOLS), None)

    async def _handle(self, viewer: ServerConnection) -> None:
        decided = self._decided.pop(viewer, None)
        if decided is None:  # gone already (:meth:`_forget`)
            return
        if isinstance(decided, str):
            self.refused += 1
            log.info("Foxglove gate: refused %s: %s", viewer.remote_address, decided)
            await viewer.close(CloseCode.POLICY_VIOLATION, close_reason(decided))
            return
        self.admitted += 1
        upstream = decided.upstream
        log.info(
            "Foxglove gate: %s watching (a %s token, until %s)",
            viewer.remote_address, decided.claims.role,
            time.strftime("%H:%M:%S", time.localtime(decided.claims.exp)),
        )  # fmt: skip
        pumps = [
            asyncio.create_task(_pipe(viewer, upstream)),
            asyncio.create_task(_pipe(upstream, viewer)),
        ]
        try:
            done, _ = await asyncio.wait(
                pumps,
                timeout=max(0.0, decided.claims.exp - self._clock()),
                return_when=asyncio.FIRST_COMPLETED,
            )
            if not done:
                await viewer.close(CloseCode.POLICY_VIOLATION, EXPIRED)
        finally:
            for pump in pumps:
                pump.cancel()
            await asyncio.gather(*pumps, return_exceptions=True)
            # The SDK's answer to the close comes behind what it still sends: read on to it.
            closing = asyncio.create_task(upstream.close())
            await _pipe(upstream, None)
            await closing

    def close(self) -> None:
        """Close every viewer's connection and stop serving."""
        if self._thread.is_alive() and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join()


async def _pipe(source: Socket, sink: Socket | None) -> None:
    """``source``'s messages to ``sink`` (None: nowhere) as they come, until either closes."""
    with contextlib.suppress(ConnectionClosed):
        async for message in source:
            if sink is not None:
                await sink.send(message)


def _bound_port(server: Server) -> int:
    return int(server.sockets[0].getsockname()[1])
