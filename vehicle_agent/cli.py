"""``autopilot vehicle`` (and ``python -m vehicle_agent``): run the Python vehicle agent."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
from pathlib import Path

from aiortc import RTCIceServer

from app.supervise import on_stop_signals
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.control import PROFILES
from vehicle_agent.events import EventLog
from vehicle_agent.signaling import SignalingError, ws_url
from vehicle_agent.turtle import RosbridgeTurtle, SimTurtle, Turtle, TurtleError
from vehicle_agent.video import VideoSourceError, open_source

log = logging.getLogger(__name__)


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 640x480, not {text!r}") from None
    # The encoders work on 4:2:0 frames, whose chroma planes halve both sides.
    if width <= 0 or height <= 0 or width % 2 or height % 2:
        raise argparse.ArgumentTypeError(f"size must be positive and even, not {text!r}")
    return width, height


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, not {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, not {text!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot vehicle``."""
    parser.add_argument(
        "--server",
        default="http://127.0.0.1:8000",
        help="the server's base URL (default http://127.0.0.1:8000)",
    )
    parser.add_argument("--room", default="default", help="room to join (default: default)")
    parser.add_argument("--name", default="vehicle", help="peer name (default: vehicle)")
    parser.add_argument(
        "--video",
        default="synthetic",
        metavar="SOURCE",
        help="'synthetic' (a moving face with frame tags), a video file (looped) or /dev/videoN",
    )
    parser.add_argument(
        "--size",
        type=_size,
        metavar="WxH",
        help="frame size (synthetic: 640x480; files, devices: their own)",
    )
    parser.add_argument("--fps", type=_positive, help="frame rate (default 30, or the file's)")
    parser.add_argument(
        "--rosbridge",
        metavar="URL",
        help="drive turtle1 through this rosbridge (ws://host:9090); default: in-process simulator",
    )
    parser.add_argument(
        "--ros", type=int, choices=(1, 2), default=1, help="ROS message type names (default 1)"
    )
    parser.add_argument(
        "--profile", choices=sorted(PROFILES), default="default", help="control timing profile"
    )
    parser.add_argument(
        "--goal-timeout",
        type=_positive,
        metavar="S",
        help="stop the turtle when no goal came for this long (default: the profile's)",
    )
    parser.add_argument(
        "--ice-server",
        action="append",
        default=[],
        metavar="URL",
        help="STUN/TURN URL for ICE (repeatable; default none: host candidates only)",
    )
    parser.add_argument(
        "--events", type=Path, metavar="PATH", help="append a JSON-lines event log here"
    )


def run(args: argparse.Namespace) -> int:
    """Run the agent until interrupted; a setup problem is one line and exit status 1."""
    # Twisted (under roslibpy) narrates every reconnection attempt at INFO.
    logging.getLogger("twisted").setLevel(logging.WARNING)
    try:
        return asyncio.run(_main(args))
    except (SignalingError, TurtleError, VideoSourceError, OSError) as exc:
        log.error("%s", exc)
        return 1


async def _main(args: argparse.Namespace) -> int:
    ws_url(args.server)  # a malformed URL is reported before anything starts
    events = EventLog(args.events)
    video = open_source(
        args.video,
        args.size,
        args.fps,
        on_frame=lambda info: events.emit(
            "frame_sent", frame=info.frame, face_x=info.face_x, face_y=info.face_y
        ),
    )
    turtle: Turtle = RosbridgeTurtle(args.rosbridge, args.ros) if args.rosbridge else SimTurtle()
    config = AgentConfig(
        server=args.server,
        room=args.room,
        name=args.name,
        profile=args.profile,
        goal_timeout_s=args.goal_timeout,
        ice_servers=[RTCIceServer(urls=url) for url in args.ice_server],
    )
    agent = Agent(config, video, turtle, events)
    task = asyncio.create_task(agent.run())
    on_stop_signals(task.cancel)
    try:
        with contextlib.suppress(asyncio.CancelledError):
            await task
    finally:
        events.close()
    log.info("vehicle agent stopped")
    return 0
