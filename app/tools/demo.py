"""``autopilot demo``: the whole system on an embedded default, with one command.

Starts the server (signaling, pages, simulated turtle with its ``/rosbridge``), a headless relay
(``autopilot relay``) and the Python vehicle agent with the synthetic face video driving the
server's turtle through ``/rosbridge``, prints the client URL and runs until interrupted. The relay
and the agent are child processes, each in its own process group: a child that dies is started
again, and SIGINT/SIGTERM ends every one of them (and whatever they started, Chromium included).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import signal
import sys
from dataclasses import dataclass

from app.protocol.constants import PROFILES
from app.protocol.urls import page_url, reachable_host
from app.server.config import Settings
from app.server.serve import RunningServer, start_in_thread
from app.supervise import Backoff, on_stop_signals, sleep_unless
from app.tools.browser import BrowserNotFound, chromium_path

log = logging.getLogger(__name__)

STOP_GRACE_S = 10.0
RESTART_FIRST_S = 1.0
RESTART_CAP_S = 30.0
# A child that ran this long before dying is restarted from the first backoff delay again.
HEALTHY_RUN_S = 60.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot demo``."""
    parser.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8000, help="port to bind (default 8000)")
    parser.add_argument("--room", default="default", help="room (default: default)")
    parser.add_argument(
        "--profile",
        choices=PROFILES,
        default="default",
        help="relay and agent profile",
    )


@dataclass
class Child:
    """One supervised child process."""

    name: str
    argv: list[str]
    process: asyncio.subprocess.Process | None = None


def children_for(base_url: str, room: str, profile: str) -> list[Child]:
    """The relay service and the vehicle agent pointed at the server at ``base_url``."""
    python = sys.executable
    rosbridge = base_url.replace("http", "ws", 1) + "/rosbridge"
    common = ["--server", base_url, "--room", room, "--profile", profile]
    return [
        Child("relay", [python, "-m", "app.cli", "relay", *common]),
        Child(
            "vehicle",
            [
                python,
                "-m",
                "app.cli",
                "vehicle",
                *common,
                "--video",
                "synthetic",
                "--rosbridge",
                rosbridge,
            ],
        ),
    ]


async def supervise(child: Child, stop: asyncio.Event) -> None:
    """Run ``child`` until ``stop``; restart it with backoff whenever it exits on its own."""
    backoff = Backoff(RESTART_FIRST_S, RESTART_CAP_S, jitter=0)
    loop = asyncio.get_running_loop()
    while not stop.is_set():
        started = loop.time()
        # A session of its own: signals to the demo's terminal do not reach it directly, and
        # the whole group (Chromium under the relay included) can be ended at once.
        child.process = await asyncio.create_subprocess_exec(*child.argv, start_new_session=True)
        log.info("started %s (pid %d)", child.name, child.process.pid)
        waiting = asyncio.create_task(child.process.wait())
        stopping = asyncio.create_task(stop.wait())
        await asyncio.wait({waiting, stopping}, return_when=asyncio.FIRST_COMPLETED)
        stopping.cancel()
        if stop.is_set():
            waiting.cancel()
            await terminate(child)
            return
        code = waiting.result()
        _kill_group(child.process.pid)  # anything it left behind
        if loop.time() - started > HEALTHY_RUN_S:
            backoff.reset()
        delay = backoff.next()
        log.warning("%s exited with status %s; restarting in %.0f s", child.name, code, delay)
        await sleep_unless(stop, delay)


async def terminate(child: Child) -> None:
    """SIGTERM the child, wait for it, then make sure nothing of its group survives."""
    process = child.process
    if process is None:
        return
    if process.returncode is None:
        process.terminate()
        try:
            await asyncio.wait_for(process.wait(), STOP_GRACE_S)
        except TimeoutError:
            log.warning("%s did not stop within %.0f s; killing it", child.name, STOP_GRACE_S)
            process.kill()
            await process.wait()
    _kill_group(process.pid)
    log.info("%s stopped", child.name)


def _kill_group(pgid: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, signal.SIGKILL)


def run(args: argparse.Namespace) -> int:
    """Start everything, print the client URL, run until SIGINT/SIGTERM."""
    try:
        chromium_path()
        server = start_in_thread(Settings(), host=args.host, port=args.port, log_level="info")
    except BrowserNotFound as exc:
        log.error("%s", exc)
        return 1
    except OSError as exc:
        log.error("cannot listen on %s:%s: %s", args.host, args.port, exc.strerror or exc)
        return 1
    try:
        asyncio.run(_main(server, args))
    finally:
        server.stop()
    log.info("demo stopped")
    return 0


async def _main(server: RunningServer, args: argparse.Namespace) -> None:
    port = server.url.rsplit(":", 1)[1]
    base = f"http://{reachable_host(args.host)}:{port}"
    stop = asyncio.Event()
    on_stop_signals(stop.set)
    children = children_for(base, args.room, args.profile)
    tasks = [asyncio.create_task(supervise(child, stop)) for child in children]
    # The one line a newcomer needs, on stdout rather than in the log.
    sys.stdout.write(
        f"\nwebrtc-autopilot demo is running. Open the client page:\n\n"
        f"    {page_url(base, 'client', args.room)}\n\n"
        f"then press Start Piloting. Ctrl-C stops everything.\n\n"
    )
    sys.stdout.flush()
    await asyncio.gather(*tasks)
