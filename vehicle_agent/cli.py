"""``autopilot vehicle`` (and ``python -m vehicle_agent``): run the Python vehicle agent."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import os
import ssl
from pathlib import Path
from urllib.parse import urlsplit

from aiortc import MediaStreamTrack, RTCIceServer

from app.arguments import (
    add_robot_option,
    add_token_option,
    add_vehicle_profile,
    non_negative_number,
    positive_number,
)
from app.metrics import add_metrics_arguments
from app.protocol.rooms import DEFAULT_ROOM
from app.protocol.ros import AUTO, ROS_SETTINGS
from app.protocol.tokens import SECRET_ENV
from app.protocol.video import VIDEO_FPS, VIDEO_SIZE
from app.supervise import on_stop_signals
from vehicle_agent import foxglove, recorder
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.core.control import PROFILES
from vehicle_agent.events import EventLog
from vehicle_agent.metrics import serve_agent_metrics
from vehicle_agent.robotlink import RobotLink, RobotLinkError, RosbridgeLink, SimLink
from vehicle_agent.rosbridge_client import CBOR, NONE, RosbridgeClient, RosbridgeError
from vehicle_agent.roscamera import CameraError, RosCamera, camera_of
from vehicle_agent.signaling import SignalingError, ws_url
from vehicle_agent.video import SweepPath, VideoSourceError, open_source

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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot vehicle``."""
    parser.add_argument(
        "--server",
        default="http://127.0.0.1:8000",
        help="the server's base URL (default http://127.0.0.1:8000)",
    )
    parser.add_argument(
        "--room", default=DEFAULT_ROOM, help=f"room to join (default: {DEFAULT_ROOM})"
    )
    parser.add_argument("--name", default="vehicle", help="peer name (default: vehicle)")
    parser.add_argument(
        "--video",
        default="synthetic",
        metavar="SOURCE",
        help="'synthetic' (a moving face with frame tags), 'two-faces' (two faces drifting, to"
        " try the target lock), a video file (looped), /dev/videoN, ros:TOPIC (the robot's"
        " camera topic through --rosbridge: sensor_msgs/CompressedImage or Image) or ros (the"
        " camera topic of the --robot description)",
    )
    parser.add_argument(
        "--size",
        type=_size,
        metavar="WxH",
        help="frame size (synthetic, ros: {}x{}; files, devices: their own)".format(*VIDEO_SIZE),
    )
    parser.add_argument(
        "--fps", type=positive_number, help=f"frame rate (default {VIDEO_FPS:g}, or the file's)"
    )
    parser.add_argument(
        "--sweep-s",
        type=positive_number,
        metavar="S",
        help=f"synthetic: seconds per cycle of the face's glides and leaps "
        f"(default {SweepPath().cycle_s:g})",
    )
    parser.add_argument(
        "--rosbridge",
        metavar="URL",
        help="drive the robot through this rosbridge (ws://host:9090); default: an in-process"
        " turtlesim",
    )
    add_robot_option(parser, "the robot driven: its topics, types and limits")
    parser.add_argument(
        "--camera-compression",
        choices=(CBOR, NONE),
        default=CBOR,
        help="ros: ask rosbridge for the camera's messages in CBOR (binary frames; the default,"
        " JSON where the server has no CBOR) or none (JSON with the image in base64)",
    )
    parser.add_argument(
        "--ros",
        choices=ROS_SETTINGS,
        default=AUTO,
        help="ROS flavour of the robot's type names when its rosapi cannot tell: 1, 2 (up to "
        "Iron) or jazzy; auto (default) learns them from rosapi topic_type",
    )
    add_vehicle_profile(parser)
    parser.add_argument(
        "--standoff",
        type=non_negative_number,
        metavar="M",
        help=f"follow: distance kept from the target (default {PROFILES['follow'].standoff_m:g} m)",
    )
    parser.add_argument(
        "--no-spawn-step",
        dest="spawn_step",
        action="store_false",
        help="do not turn the turtle to face up (θ = π/2) at start (a turtlesim's only step)",
    )
    parser.add_argument(
        "--goal-timeout",
        type=positive_number,
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
    add_token_option(parser, "vehicle")
    parser.add_argument(
        "--ca-file",
        type=Path,
        metavar="PEM",
        help="trust this CA for an https:// server and a wss:// rosbridge (--self-signed: ca.pem)",
    )
    recorder.add_arguments(parser)
    foxglove.add_arguments(parser)
    add_metrics_arguments(parser)


def tls_context(ca_file: Path | None) -> ssl.SSLContext:
    """A client context trusting ``ca_file``, or the system's CAs; names are always checked."""
    try:
        return ssl.create_default_context(cafile=None if ca_file is None else str(ca_file))
    except (OSError, ssl.SSLError) as exc:
        raise OSError(f"cannot use --ca-file {ca_file}: {exc}") from exc


def same_server(server: str, rosbridge: str) -> bool:
    """True when ``rosbridge`` is the server's own ``/rosbridge`` (same host and port), the only
    rosbridge the token is sent to."""
    ours, theirs = urlsplit(server), urlsplit(rosbridge)
    return (ours.hostname, ours.port) == (theirs.hostname, theirs.port)


def run(args: argparse.Namespace) -> int:
    """Run the agent until interrupted; a setup problem is one line and exit status 1."""
    if not args.robot.turtlesim and not args.rosbridge:
        log.error(
            "--robot %s needs --rosbridge URL: the in-process simulator is a turtlesim",
            args.robot.name,
        )
        return 2
    try:
        return asyncio.run(_main(args))
    except (
        SignalingError,
        RobotLinkError,
        RosbridgeError,
        VideoSourceError,
        recorder.RecorderError,
        OSError,
    ) as exc:
        log.error("%s", exc)
        return 1


async def _main(args: argparse.Namespace) -> int:
    ws_url(args.server)  # a malformed URL is reported before anything starts
    robot = args.robot
    events = EventLog(args.events)
    record = recorder.settings_from(args, args.room)
    # A folder that cannot be written is said now, not at the first write.
    flight = (
        None
        if record is None
        else recorder.FlightRecorder(record, extra=foxglove.recorded_channels())
    )
    # The token goes only to the server's own /rosbridge.
    rosbridge_token = (
        args.token if args.rosbridge and same_server(args.server, args.rosbridge) else None
    )
    camera = None
    metrics = None
    # One rosbridge connection for the robot: the link drives it, the camera borrows it.
    client = (
        RosbridgeClient(args.rosbridge, rosbridge_token, tls_context(args.ca_file))
        if args.rosbridge
        else None
    )
    live = None
    viewer = None
    try:
        live = foxglove.start(args, robot, os.environ.get(SECRET_ENV) or None, args.room)
        video = await _open_video(args, events, client)
        link: RobotLink = SimLink() if client is None else RosbridgeLink(client, args.ros, robot)
        config = AgentConfig(
            server=args.server,
            room=args.room,
            name=args.name,
            profile=args.profile,
            goal_timeout_s=args.goal_timeout,
            standoff_m=args.standoff,
            spawn_step=args.spawn_step,
            robot=robot,
            ice_servers=[RTCIceServer(urls=url) for url in args.ice_server],
            token=args.token,
            tls=tls_context(args.ca_file),
        )
        agent = Agent(config, video, link, events)
        if flight is not None:
            events.listeners.append(flight.on_event)
            events.listeners.append(foxglove.recording_scene(flight, robot).on_event)
            camera = asyncio.create_task(flight.record_video(agent.camera_tap()), name="record")
        if live is not None:
            events.listeners.append(live.on_event)
            viewer = asyncio.create_task(live.stream_video(agent.camera_tap()), name="foxglove")
        metrics = serve_agent_metrics(args, events)
        task = asyncio.create_task(agent.run())
        on_stop_signals(task.cancel)
        with contextlib.suppress(asyncio.CancelledError):
            await task
    finally:
        if client is not None:
            await client.close()
        if camera is not None:
            camera.cancel()
        if viewer is not None:
            viewer.cancel()
        if live is not None:
            await foxglove.close(live)
        if flight is not None:
            # Also when setting up failed: the recorder's writer thread would keep the process.
            await _close_recorder(flight, events)
        events.close()
        if metrics is not None:
            metrics.close()
    log.info("vehicle agent stopped")
    return 0


async def _open_video(
    args: argparse.Namespace, events: EventLog, client: RosbridgeClient | None
) -> MediaStreamTrack:
    """The ``--video`` track; a camera topic is subscribed to (through ``client``, the robot's
    one rosbridge connection) before anything else starts."""
    found = camera_of(args.video, args.robot)
    if found is None:
        return open_source(
            args.video, args.size, args.fps, on_frame=events.emit, sweep_s=args.sweep_s
        )
    topic, described = found
    if client is None:
        raise CameraError(f"--video {args.video} reads the camera through --rosbridge URL")
    camera = RosCamera(
        client,
        topic,
        described=described,
        size=args.size or VIDEO_SIZE,
        fps=args.fps or VIDEO_FPS,
        compression=args.camera_compression,
        on_frame=events.emit,
    )
    await camera.start()
    return camera


async def _close_recorder(flight: recorder.FlightRecorder, events: EventLog) -> None:
    """Finish the recording, and log and record what it held and cost."""
    await flight.close()
    totals = flight.totals()
    log.info(
        "flight recorder: %d images, %d messages (%d dropped) in %d file(s), %d of %d "
        "camera frames held; its CPU %.2f s over %.0f s",
        totals.images,
        totals.messages,
        totals.dropped,
        totals.files,
        totals.frames_held,
        totals.frames,
        totals.cpu_s,
        totals.seconds,
    )
    events.emit(totals)
