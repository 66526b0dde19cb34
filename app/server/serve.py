"""``autopilot serve``: the server under uvicorn, and a background-thread variant for tests."""

from __future__ import annotations

import argparse
import asyncio
import logging
import socket
import threading
from dataclasses import dataclass

import uvicorn
from pydantic import ValidationError

from app.protocol.constants import ROLES
from app.protocol.errors import describe
from app.protocol.urls import page_url, reachable_host, ws_endpoint
from app.server.app import create_app
from app.server.config import Settings
from app.vision.spec import SpecError

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot serve``."""
    parser.add_argument("--host", help="address to bind (default: AUTOPILOT_HOST or 127.0.0.1)")
    parser.add_argument("--port", type=int, help="port to bind (default: AUTOPILOT_PORT or 8000)")


def page_urls(base: str, room: str = "default") -> dict[str, str]:
    """The URLs a person opens, keyed by role."""
    return {role: page_url(base, role, room) for role in ROLES}


def run(args: argparse.Namespace) -> int:
    """Serve until interrupted; a bad setting or operations spec is one line and exit 1."""
    try:
        settings = Settings()
        app = create_app(settings)
    except ValidationError as exc:
        log.error("cannot start: %s", describe(exc))
        return 1
    except SpecError as exc:
        log.error("cannot start: %s", exc)
        return 1
    host = args.host or settings.host
    port = args.port or settings.port
    base = f"http://{reachable_host(host)}:{port}"
    for role, url in page_urls(base).items():
        log.info("%s page: %s", role, url)
    uvicorn.run(app, host=host, port=port, log_level="info")
    return 0


@dataclass
class RunningServer:
    """A server started by :func:`start_in_thread`."""

    url: str
    server: uvicorn.Server
    thread: threading.Thread

    @property
    def ws_url(self) -> str:
        """The signaling endpoint."""
        return ws_endpoint(self.url)

    def stop(self) -> None:
        """Ask uvicorn to exit and wait for its thread."""
        self.server.should_exit = True
        self.thread.join(timeout=10)


def start_in_thread(
    settings: Settings | None = None,
    host: str = "127.0.0.1",
    port: int = 0,
    log_level: str = "warning",
) -> RunningServer:
    """Start the app in a daemon thread (``port=0``: a free one); returns once it accepts
    connections. Raises ``OSError`` when the address cannot be bound."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    port = sock.getsockname()[1]
    config = uvicorn.Config(create_app(settings), log_level=log_level, lifespan="on")
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
    return RunningServer(url=f"http://{host}:{port}", server=server, thread=thread)
