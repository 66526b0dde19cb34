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
import secrets
import signal
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from pydantic import ValidationError

from app.arguments import add_vehicle_profile, port
from app.chromium import BrowserNotFound, chromium_path
from app.metrics import add_metrics_arguments, serve_metrics
from app.protocol import tokens
from app.protocol.urls import page_url, reachable_host
from app.server import tls
from app.server.config import Settings, describe_settings_error
from app.server.hosts import ANY_ADDRESS
from app.server.serve import (
    RunningServer,
    add_robot_argument,
    reachable_hosts,
    settings_from,
    start_in_thread,
)
from app.simulators import SimulatorName
from app.supervise import Backoff, on_stop_signals, sleep_unless
from vehicle_agent import foxglove, recorder
from vehicle_agent.video import SYNTHETIC, TWO_FACES

log = logging.getLogger(__name__)

STOP_GRACE_S = 10.0
RESTART_FIRST_S = 1.0
RESTART_CAP_S = 30.0
# A child that ran this long before dying is restarted from the first backoff delay again.
HEALTHY_RUN_S = 60.0
# The demo's tokens last as long as a demo may plausibly run; without AUTOPILOT_SECRET they are
# signed with a secret made for this run, so they end with it anyway.
DEMO_TOKEN_TTL_S = 30 * 24 * 3600
# The agent's --video values the demo offers.
DEMO_VIDEOS = (SYNTHETIC, TWO_FACES)
# The agent's --video for a robot that carries its camera: the topic its description names.
ROBOT_CAMERA = "ros"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot demo``."""
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind (default 127.0.0.1); 0.0.0.0 or :: (every address, for pages on"
        " other machines) turns on HTTPS with a local CA, as browsers give the camera only to"
        " HTTPS pages",
    )
    parser.add_argument("--port", type=port, default=8000, help="port to bind (default 8000)")
    parser.add_argument("--room", default="default", help="room (default: default)")
    add_vehicle_profile(parser)
    parser.add_argument(
        "--video",
        choices=DEMO_VIDEOS,
        default=DEMO_VIDEOS[0],
        help="the agent's synthetic video: a face sweeping across (synthetic, the default) or"
        " two faces drifting, to try the target lock (two-faces); with --robot diffdrive the"
        " video is the robot's own camera",
    )
    add_robot_argument(parser)
    tls.add_arguments(parser)
    recorder.add_arguments(parser)
    parser.add_argument(
        "--foxglove-port",
        type=port,
        default=foxglove.DEFAULT_PORT,
        help=f"the agent serves Foxglove on 127.0.0.1 at this port (default"
        f" {foxglove.DEFAULT_PORT}; docs/foxglove.md)",
    )
    # The server's metrics (the relay's and the agent's are each their own process's).
    add_metrics_arguments(parser)


@dataclass
class Child:
    """One supervised child process."""

    name: str
    argv: list[str]
    # Added to the demo's environment: the child's token travels here, not in its argv.
    env: dict[str, str] = field(default_factory=dict)
    process: asyncio.subprocess.Process | None = None


def children_for(
    base_url: str,
    room: str,
    profile: str,
    secret: str | None = None,
    ca_file: Path | None = None,
    video: str = DEMO_VIDEOS[0],
    vehicle_args: Sequence[str] = (),
    robot: SimulatorName = "turtlesim",
) -> list[Child]:
    """The relay service and the vehicle agent pointed at the server at ``base_url``, each
    with a token for its role in ``room`` when there is a ``secret``; ``vehicle_args`` go to the
    agent as they are (the flight recorder's options). The agent drives the server's ``robot``
    (its description's topics and limits): turtlesim's turtle filmed by ``video``, or the room's
    diffdrive robot, whose video is its own camera's topic."""
    python = sys.executable
    if robot == "diffdrive":
        video = ROBOT_CAMERA
    rosbridge = base_url.replace("http", "ws", 1) + "/rosbridge"
    common = ["--server", base_url, "--room", room]
    if ca_file is not None:
        common += ["--ca-file", str(ca_file)]

    def token_env(role: tokens.Role) -> dict[str, str]:
        if secret is None:
            return {}
        now = time.time()
        return {
            tokens.ACCESS_TOKEN_ENV: tokens.sign(
                secret, room, role, now=now, ttl_s=DEMO_TOKEN_TTL_S
            )
        }

    return [
        # The relay paces its snapshots by the relay profile this vehicle profile pairs with, and
        # starts with its operation.
        Child(
            "relay",
            [python, "-m", "app.cli", "relay", *common, "--profile", profile],
            token_env("relay"),
        ),
        Child(
            "vehicle",
            [
                python,
                "-m",
                "app.cli",
                "vehicle",
                *common,
                "--profile",
                profile,
                "--video",
                video,
                "--rosbridge",
                rosbridge,
                "--robot",
                robot,
                *vehicle_args,
            ],
            token_env("vehicle"),
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
        child.process = await asyncio.create_subprocess_exec(
            *child.argv, start_new_session=True, env={**os.environ, **child.env}
        )
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
    # Listening beyond this machine means pages opened elsewhere: they need HTTPS for a camera.
    if args.host in ANY_ADDRESS and not args.certfile:
        args.self_signed = True
    try:
        chromium_path()
        files = tls.from_arguments(args)
        settings = settings_from(args)
        # The demo mints its own tokens: with a secret made for this run when none is set.
        if settings.secret is None:
            settings = settings.model_copy(update={"secret": secrets.token_urlsafe(32)})
        server = start_in_thread(
            settings, host=args.host, port=args.port, log_level="info", tls_files=files
        )
    except (BrowserNotFound, ValueError) as exc:
        reason = describe_settings_error(exc) if isinstance(exc, ValidationError) else exc
        log.error("cannot start: %s" if isinstance(exc, ValidationError) else "%s", reason)
        return 1
    except OSError as exc:
        log.error("cannot listen on %s:%s: %s", args.host, args.port, exc.strerror or exc)
        return 1
    try:
        metrics = serve_metrics(args, server.metrics.registry)
    except OSError as exc:
        server.stop()
        log.error("%s", exc)
        return 1
    try:
        asyncio.run(_main(server, args, settings, files))
    finally:
        if metrics is not None:
            metrics.close()
        server.stop()
    log.info("demo stopped")
    return 0


def client_urls(scheme: str, host: str, port: str, room: str, token: str | None) -> list[str]:
    """The client page URLs to print: every address of this machine when bound to all of them
    (the loopback ones last), else the bound address."""
    hosts = reachable_hosts(host) if host in ANY_ADDRESS else [host]
    fragment = f"#token={token}" if token else ""
    return [page_url(f"{scheme}://{h}:{port}", "client", room) + fragment for h in hosts]


async def _main(
    server: RunningServer, args: argparse.Namespace, settings: Settings, files: tls.TlsFiles | None
) -> None:
    scheme = "https" if files is not None else "http"
    port = server.url.rsplit(":", 1)[1]
    base = f"{scheme}://{reachable_host(args.host)}:{port}"
    stop = asyncio.Event()
    on_stop_signals(stop.set)
    ca_file = files.ca_file if files is not None else None
    children = children_for(
        base,
        args.room,
        args.profile,
        settings.secret,
        ca_file,
        args.video,
        [*recorder.arguments_of(args), "--foxglove", f"127.0.0.1:{args.foxglove_port}"],
        settings.robot,
    )
    tasks = [asyncio.create_task(supervise(child, stop)) for child in children]
    token = None
    if settings.secret is not None:
        token = tokens.sign(
            settings.secret, args.room, "client", now=time.time(), ttl_s=DEMO_TOKEN_TTL_S
        )
    urls = "\n".join(f"    {url}" for url in client_urls(scheme, args.host, port, args.room, token))
    # The one line a newcomer needs, on stdout rather than in the log.
    sys.stdout.write(
        f"\nwebrtc-autopilot demo is running. Open the client page:\n\n{urls}\n\n"
        f"then press Connect, Join Room and Start Piloting. Ctrl-C stops everything.\n\n"
        f"Foxglove (Open connection, Foxglove WebSocket): ws://127.0.0.1:{args.foxglove_port}\n\n"
    )
    sys.stdout.flush()
    await asyncio.gather(*tasks)
