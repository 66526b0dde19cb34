"""Prometheus ``/metrics`` on a listener of its own, shared by every long-running command.

``--metrics-port PORT`` opens it (off by default) on ``--metrics-host`` (127.0.0.1 by default:
metrics name rooms' counts and refusals, nothing a stranger needs). Each process exports its own
:class:`~prometheus_client.CollectorRegistry`, never the library's global one, so that several
apps in one process (the tests, the demo's server thread) never share or clash over a series.
What each command exports is in ``docs/operations.md``; the metrics themselves live beside the
code they count (:mod:`app.server.metrics`, :mod:`vehicle_agent.metrics`,
:mod:`app.relay.metrics`).
"""

from __future__ import annotations

import argparse
import logging
import threading
from dataclasses import dataclass
from typing import Final
from wsgiref.simple_server import WSGIServer

from prometheus_client import CollectorRegistry, start_http_server

from app.arguments import port

log = logging.getLogger(__name__)

DEFAULT_HOST: Final = "127.0.0.1"


def add_metrics_arguments(parser: argparse.ArgumentParser) -> None:
    """``--metrics-port`` and ``--metrics-host``: where this process serves ``/metrics``."""
    parser.add_argument(
        "--metrics-port",
        type=port,
        metavar="PORT",
        help="serve Prometheus metrics at http://HOST:PORT/metrics (default: off)",
    )
    parser.add_argument(
        "--metrics-host",
        default=DEFAULT_HOST,
        metavar="HOST",
        help=f"address of the metrics listener (default {DEFAULT_HOST})",
    )


@dataclass
class MetricsServer:
    """A running ``/metrics`` listener (a daemon thread); :meth:`close` stops it."""

    host: str
    port: int
    httpd: WSGIServer
    thread: threading.Thread

    @property
    def url(self) -> str:
        """The address to scrape."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/metrics"

    def close(self) -> None:
        """Stop serving and free the port."""
        self.httpd.shutdown()
        self.httpd.server_close()
        self.thread.join(timeout=5)


def start_metrics_server(
    registry: CollectorRegistry, port: int, host: str = DEFAULT_HOST
) -> MetricsServer:
    """Serve ``registry`` at ``http://host:port/metrics`` (``port=0``: a free one).

    Raises ``OSError``, naming the address, when it cannot be bound.
    """
    try:
        httpd, thread = start_http_server(port, addr=host, registry=registry)
    except OSError as exc:
        raise OSError(
            f"cannot serve metrics on {host}:{port}: {exc.strerror or exc}"
            " (choose another --metrics-port)"
        ) from exc
    server = MetricsServer(host, httpd.server_port, httpd, thread)
    log.info("metrics: %s", server.url)
    return server


def serve_metrics(args: argparse.Namespace, registry: CollectorRegistry) -> MetricsServer | None:
    """The listener the command line asks for (:func:`add_metrics_arguments`), or None."""
    if args.metrics_port is None:
        return None
    return start_metrics_server(registry, args.metrics_port, args.metrics_host)
