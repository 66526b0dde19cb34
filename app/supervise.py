"""Supervision helpers every long-running process shares: backoff, stop signals, logging.

Imports nothing of the project's own, so the agent, the server and the tools can all use it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import signal
import socket
import subprocess
from collections.abc import Awaitable, Callable
from typing import Any


class Backoff:
    """Exponential backoff with jitter: ``first``, twice that, ... up to ``cap`` seconds."""

    def __init__(self, first: float = 0.5, cap: float = 8.0, jitter: float = 0.1) -> None:
        self.first, self.cap, self.jitter = first, cap, jitter
        self._next = first

    def next(self) -> float:
        """The delay to wait now; the following one doubles."""
        delay = self._next
        self._next = min(self.cap, self._next * 2)
        return delay * random.uniform(1 - self.jitter, 1 + self.jitter)

    def reset(self) -> None:
        """After a success, start again from the first delay."""
        self._next = self.first


async def sleep_unless(stop: asyncio.Event, delay: float) -> None:
    """Wait ``delay`` seconds, or less if ``stop`` is set meanwhile."""
    with contextlib.suppress(TimeoutError):
        await asyncio.wait_for(stop.wait(), delay)


def on_stop_signals(callback: Callable[[], object]) -> None:
    """Call ``callback`` on SIGINT or SIGTERM (from the running event loop)."""
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, callback)


async def run_until_stopped(run: Callable[[asyncio.Event], Awaitable[object]]) -> None:
    """Await ``run(stop)``; SIGINT or SIGTERM sets ``stop`` so it can end cleanly."""
    stop = asyncio.Event()
    on_stop_signals(stop.set)
    await run(stop)


def configure_logging(verbose: bool = False) -> None:
    """One log format for every command."""
    logging.basicConfig(
        level=logging.DEBUG if verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now (for a child process that cannot take port 0)."""
    with socket.socket() as sock:
        sock.bind((host, 0))
        port: int = sock.getsockname()[1]
        return port


def stop_process(process: subprocess.Popen[Any], grace_s: float) -> None:
    """SIGTERM ``process`` if it still runs; SIGKILL it if it has not exited ``grace_s`` later."""
    if process.poll() is not None:
        return
    process.terminate()
    try:
        process.wait(timeout=grace_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
