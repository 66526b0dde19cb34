"""``autopilot serve``: the server under uvicorn, and a background-thread variant for tests."""

from __future__ import annotations

import argparse
import asyncio
import errno
import logging
import socket
import struct
import threading
from dataclasses import dataclass
from typing import Any, Final

import uvicorn
from pydantic import ValidationError
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol
from websockets.protocol import State

from app.arguments import port
from app.metrics import add_metrics_arguments, serve_metrics
from app.protocol.rooms import ROLES
from app.protocol.ros import DEFAULT_FLAVOUR, ROS_FLAVOURS
from app.protocol.urls import page_url, reachable_host, ws_endpoint
from app.server import tls
from app.server.config import Settings, describe_settings_error
from app.server.hosts import ANY_ADDRESS
from app.server.metrics import ServerMetrics
from app.simulators import DEFAULT_SIMULATOR, SIMULATOR_HELP, SIMULATOR_NAMES
from app.vision.spec import SpecError

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot serve``."""
    parser.add_argument("--host", help="address to bind (default: AUTOPILOT_HOST or 127.0.0.1)")
    parser.add_argument("--port", type=port, help="port to bind (default: AUTOPILOT_PORT or 8000)")
    parser.add_argument(
        "--ros",
        choices=ROS_FLAVOURS,
        help="ROS flavour the simulated robot speaks: 1, 2 (up to Iron) or jazzy "
        f"(default: AUTOPILOT_ROS or {DEFAULT_FLAVOUR})",
    )
    add_robot_argument(parser)
    tls.add_arguments(parser)
    add_metrics_arguments(parser)


def add_robot_argument(parser: argparse.ArgumentParser) -> None:
    """``--robot``: which robot the server simulates (``autopilot serve`` and ``demo``)."""
    parser.add_argument(
        "--robot",
        choices=SIMULATOR_NAMES,
        help="the simulated robot: "
        + ", or ".join(f"{name}, {what}" for name, what in SIMULATOR_HELP.items())
        + f" (default: AUTOPILOT_ROBOT or {DEFAULT_SIMULATOR})",
    )


def settings_from(args: argparse.Namespace) -> Settings:
    """The environment's settings, with what the command line sets over them."""
    given = {name: getattr(args, name, None) for name in ("ros", "robot", "host")}
    return Settings(**{name: value for name, value in given.items() if value})


def page_urls(base: str, room: str = "default") -> dict[str, str]:
    """The URLs a person opens, keyed by role."""
    return {role: page_url(base, role, room) for role in ROLES}


def reachable_hosts(host: str) -> list[str]:
    """The hosts to put in URLs for a server bound to ``host``: every address of this machine
    when bound to all of them (the loopback ones last), else the bound address."""
    if host not in ANY_ADDRESS:
        return [reachable_host(host)]
    _, addresses = tls.machine_names()
    ordered = sorted(addresses, key=lambda a: (a.is_loopback, a.version))
    return [str(a) if a.version == 4 else f"[{a}]" for a in ordered]


def port_in_use(host: str, port: int) -> bool:
    """Whether another process listens on ``port`` at ``host`` already (checked by binding)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as exc:
            return exc.errno == errno.EADDRINUSE
    return False


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted; a bad setting or operations spec is one line and exit 1."""
    try:
        settings = settings_from(args)
    except ValidationError as exc:
        log.error("cannot start: %s", describe_settings_error(exc))
        return 1
    # Imported here: FastAPI costs half a CPU-second, which a bad setting need not wait for.
    from app.server.app import create_app

    try:
        app = create_app(settings)
    except SpecError as exc:
        log.error("cannot start: %s", exc)
        return 1
    try:
        files = tls.from_arguments(args)
    except ValueError as exc:
        log.error("cannot start: %s", exc)
        return 1
    host = settings.host
    port = args.port or settings.port
    # Before any URL is printed: a port already taken fails here in one line, not in uvicorn.
    if port_in_use(host, port):
        log.error(
            "cannot start: port %d on %s is already in use (another autopilot serve?);"
            " stop that process or choose another with --port",
            port,
            host,
        )
        return 1
    try:
        metrics = serve_metrics(args, app.state.metrics.registry)
    except OSError as exc:
        log.error("cannot start: %s", exc)
        return 1
    scheme = "http" if files is None else "https"
    bases = [f"{scheme}://{h}:{port}" for h in reachable_hosts(host)]
    for role, url in page_urls(bases[0]).items():
        log.info("%s page: %s", role, url)
    if len(bases) > 1:
        log.info("the same pages at: %s", ", ".join(bases[1:]))
    if settings.secret is not None:
        log.info(
            "pages need a token (AUTOPILOT_SECRET is set): mint one with"
            " AUTOPILOT_SECRET=... autopilot token --room default --role client --server %s",
            bases[0],
        )
    elif host in ANY_ADDRESS and files is None:
        log.warning(
            "listening on every address over plain HTTP with no AUTOPILOT_SECRET:"
            " anyone on the network can drive the robot (set AUTOPILOT_SECRET, add --self-signed)"
        )
    try:
        uvicorn.run(
            app,
            **uvicorn_options(settings, files),
            host=host,
            port=port,
            log_level="info",
        )
    finally:
        if metrics is not None:
            metrics.close()
    return 0


class _QuietInvalidUtf8(logging.Filter):
    """uvicorn logs a traceback for every text frame that is not UTF-8 (then closes with 1007,
    as RFC 6455 requires); one line says the same without letting a peer flood the log."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.getMessage().startswith("Invalid UTF-8 sequence"):
            record.msg, record.args = "invalid UTF-8 in a text frame: closed with 1007", ()
            record.levelno, record.levelname = logging.WARNING, "WARNING"
            record.exc_info = record.exc_text = None
        return True


# What each WebSocket connection may hold unsent below the app: the kernel's send buffer (Linux
# gives twice this) and asyncio's write buffer above it. Left to itself Linux grows the first to
# 4 MiB, so a peer that never reads took megabytes before the writer ever waited: until then the
# server went on making and sending it messages, and only then did its outbox fill. With small
# buffers a peer that does not read is seen as one within a few dozen KB.
SEND_BUFFER_BYTES: Final = 16 * 1024


# Once either side has begun to close a WebSocket, the peer has this long to answer (or to read
# what is left) before the TCP connection is aborted. uvicorn's own close waits for its write
# buffer to drain, which a peer that never reads never lets happen: every socket closed for a
# flood (1009, 1008, 1013) stayed open for as long as that peer did.
CLOSE_ABORT_S: Final = 3.0


class _SansIOWebSocket(WebSocketsSansIOProtocol):
    """uvicorn's sans-I/O WebSocket protocol with a bounded send buffer, a bounded close and
    without one crash: a text frame that is not UTF-8 makes it close with 1007, and a second
    such frame read in the same chunk made it try to close again ("Fatal error:
    protocol.data_received() call failed", InvalidState). Frames that arrive once the closing
    handshake has begun are dropped, as RFC 6455 allows. A close the peer does not complete
    within :data:`CLOSE_ABORT_S` aborts the connection."""

    _abort_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        """Bound what the connection holds unsent (:data:`SEND_BUFFER_BYTES`)."""
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        if isinstance(transport, asyncio.WriteTransport):
            transport.set_write_buffer_limits(high=SEND_BUFFER_BYTES)
        super().connection_made(transport)

    def connection_lost(self, exc: Exception | None) -> None:
        """The connection is gone: nothing is left to abort."""
        if self._abort_timer is not None:
            self._abort_timer.cancel()
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        """Read as uvicorn does; a close begun by either side starts the abort timer."""
        super().data_received(data)
        self._abort_if_unanswered()

    async def send(self, message: Any) -> None:
        """Send as uvicorn does; a close (or a refused handshake) starts the abort timer."""
        await super().send(message)
        self._abort_if_unanswered()

    def _abort_if_unanswered(self) -> None:
        closing = self.close_sent or self.conn.state in (State.CLOSING, State.CLOSED)
        if closing and self._abort_timer is None and self.transport is not None:
            self._abort_timer = self.loop.call_later(CLOSE_ABORT_S, self._abort)

    def _abort(self) -> None:
        """Drop the connection, and what the kernel still holds for the peer: a reset."""
        sock = self.transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        self.transport.abort()

    def send_receive_event_to_app(self) -> None:
        """Hand a whole message to the app, unless the connection is already closing."""
        if self.conn.state is not State.OPEN:
            self.frames = []
            return
        super().send_receive_event_to_app()


class _HeaderTimeoutHttp(HttpToolsProtocol):
    """uvicorn's HTTP protocol (httptools) dropping a request whose headers do not all arrive
    within ``header_timeout_s`` of its start: uvicorn has no such limit, and a peer sending
    headers a byte at a time held a connection for as long as it liked."""

    header_timeout_s: float = 10.0
    _header_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        """A connection: its first request's headers are due."""
        super().connection_made(transport)
        self._await_headers()

    def on_message_begin(self) -> None:
        """A request begins (the next on a kept-alive connection): its headers are due."""
        super().on_message_begin()
        self._await_headers()

    def on_headers_complete(self) -> None:
        """Every header arrived in time."""
        self._stop_header_timer()
        super().on_headers_complete()

    def connection_lost(self, exc: Exception | None) -> None:
        """The connection is gone: nothing is due."""
        self._stop_header_timer()
        super().connection_lost(exc)

    def _await_headers(self) -> None:
        if self._header_timer is None:
            self._header_timer = self.loop.call_later(self.header_timeout_s, self._headers_late)

    def _stop_header_timer(self) -> None:
        if self._header_timer is not None:
            self._header_timer.cancel()
            self._header_timer = None

    def _headers_late(self) -> None:
        self._header_timer = None
        log.info(
            "dropping a connection whose request headers took over %g s", self.header_timeout_s
        )
        self.transport.abort()


def uvicorn_options(settings: Settings, files: tls.TlsFiles | None = None) -> dict[str, Any]:
    """What every uvicorn we start needs: the WebSocket frame size limit from ``settings``
    (uvicorn refuses a larger frame before buffering it, closing with 1009), its header
    timeout, the bounded close (:data:`CLOSE_ABORT_S`) and TLS ``files``."""
    logger = logging.getLogger("uvicorn.error")
    if not any(isinstance(f, _QuietInvalidUtf8) for f in logger.filters):
        logger.addFilter(_QuietInvalidUtf8())
    http = type(
        "HeaderTimeoutHttp", (_HeaderTimeoutHttp,), {"header_timeout_s": settings.header_timeout_s}
    )
    return {
        "http": http,
        "ws": _SansIOWebSocket,
        "ws_max_size": settings.max_message_bytes,
        "ssl_certfile": None if files is None else str(files.certfile),
        "ssl_keyfile": None if files is None else str(files.keyfile),
    }


# How long a server started by start_in_thread waits for its connections' handlers to end once
# asked to stop, before it cancels them and shuts the app down (the fleet bus leaves Redis). By
# default uvicorn waits for as long as they take: the likely way a test's server, and its fleet
# bus, outlived the Redis its test had stopped (two suite runs printed the bus's failed ticks).
GRACEFUL_SHUTDOWN_S: Final = 5
# And how long after that for the app's own shutdown.
STOP_TIMEOUT_S: Final = 10


@dataclass
class RunningServer:
    """A server started by :func:`start_in_thread`."""

    url: str
    server: uvicorn.Server
    thread: threading.Thread
    # The app's metrics (their registry is what ``--metrics-port`` serves).
    metrics: ServerMetrics

    @property
    def ws_url(self) -> str:
        """The signaling endpoint (``wss://`` when served over HTTPS)."""
        return ws_endpoint(self.url)

    def stop(self) -> None:
        """Ask uvicorn to exit and wait for its thread; raises ``RuntimeError`` if it lives on
        (a server left running would go on talking to what its caller stops next, its Redis)."""
        self.server.should_exit = True
        self.thread.join(timeout=GRACEFUL_SHUTDOWN_S + STOP_TIMEOUT_S)
        if self.thread.is_alive():
            raise RuntimeError(f"the server at {self.url} did not stop")


def start_in_thread(
    settings: Settings | None = None,
    host: str = "127.0.0.1",
    port: int = 0,
    log_level: str = "warning",
    tls_files: tls.TlsFiles | None = None,
) -> RunningServer:
    """Start the app in a daemon thread (``port=0``: a free one); returns once it accepts
    connections. Raises ``OSError`` when the address cannot be bound."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    port = sock.getsockname()[1]
    from app.server.app import create_app

    settings = settings or Settings()
    if settings.host != host:  # the address bound is a name the server answers (hosts.py)
        settings = settings.model_copy(update={"host": host})
    app = create_app(settings)
    config = uvicorn.Config(
        app,
        **uvicorn_options(settings, tls_files),
        log_level=log_level,
        lifespan="on",
        timeout_graceful_shutdown=GRACEFUL_SHUTDOWN_S,
    )
    server = uvicorn.Server(config)
    thread = threading.Thread(
        target=lambda: asyncio.run(server.serve(sockets=[sock])), daemon=True, name="uvicorn"
    )
    thread.start()
    for _ in range(500):
        if server.started:
            break
        threading.Event().wait(0.01)
    else:
        raise RuntimeError("server did not start within 5 s")
    scheme = "http" if tls_files is None else "https"
    return RunningServer(
        url=f"{scheme}://{host}:{port}", server=server, thread=thread, metrics=app.state.metrics
    )
