"""Live in Foxglove: what the vehicle sees and does, served with the Foxglove SDK and recorded
alike (docs/foxglove.md).

``autopilot vehicle --foxglove [HOST:]PORT`` serves the Foxglove WebSocket protocol
(:class:`FoxgloveLive`), where ``foxglove_bridge`` would run on a ROS robot. Its channels:

- the camera (:data:`IMAGE_TOPIC`, ``foxglove.CompressedImage``), one JPEG per camera frame at
  most and only the newest: a slow viewer skips frames, it never queues them;
- the relay's detection for each goal (:data:`ANNOTATIONS_TOPIC`, ``foxglove.ImageAnnotations``
  on that image: the target's box, its point and a label);
- the camera's calibration from the robot description's field of view
  (:data:`CALIBRATION_TOPIC`, ``foxglove.CameraCalibration``; a robot with a camera only);
- the robot's pose (:data:`POSE_TOPIC`, ``foxglove.PoseInFrame`` in ``odom``) and the transforms
  ``odom`` → ``base_link`` → ``camera`` (:data:`TF_TOPIC`, ``foxglove.FrameTransforms``);
- the pilot's events as ``foxglove.Log`` (:data:`LOG_TOPIC`) and the link's health as JSON
  (:data:`HEALTH_TOPIC`);
- the flight recording's JSON channels (``app/recording.py``: goals, Twists, poses, modes, drive
  commands, searches, link events), on the same topics with the same schemas.

Message times are capture times: an image's, its goal's annotations', and the Twist that goal
caused all carry the capture time of the camera frame they came from (its frame tag), so they
line up on Foxglove's timeline. Nothing is built for a channel nobody subscribes to
(``has_sinks``), and the camera is not even JPEG-encoded then.

:class:`Scene` turns the agent's events into these messages, for the live server and for the
flight recorder alike (``vehicle_agent/recorder.py`` writes the same topics and schemas).

Safety: the server advertises no capability, so a viewer can publish nothing and call nothing: it
cannot move the robot. It binds to 127.0.0.1 unless a host is given. The SDK checks no token, so
with ``AUTOPILOT_SECRET`` set (the server asks for tokens) and another host, the SDK's server
listens on 127.0.0.1 behind a TLS front that asks each viewer for a token of the vehicle's room
(:mod:`vehicle_agent.foxglove_gate`), and without TLS files the agent refuses to start
(:func:`exposure_error`). A viewer that stops reading loses
the oldest of its :data:`BACKLOG` queued messages (the SDK's rule), never the loop's time: logging
a message only queues it for the SDK's own threads.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import contextlib
import ipaddress
import json
import logging
import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, get_args

import av
import foxglove
from aiortc import MediaStreamTrack
from foxglove import channels as fc
from foxglove import messages as fm

from app import recording
from app.arguments import port
from app.protocol import events as ev
from app.protocol import tokens
from app.protocol.robot import Robot
from vehicle_agent.core.frame_times import FrameTimes
from vehicle_agent.foxglove_gate import FoxgloveGate, server_tls
from vehicle_agent.recorder import ExtraChannel, FlightRecorder, encode_jpeg, frame_tag

log = logging.getLogger(__name__)

DEFAULT_HOST: Final = "127.0.0.1"
DEFAULT_PORT: Final = 8765
IMAGE_TOPIC: Final = recording.IMAGE_TOPIC
ANNOTATIONS_TOPIC: Final = "/camera/annotations"
CALIBRATION_TOPIC: Final = "/camera/calibration"
POSE_TOPIC: Final = "/robot/pose"
TF_TOPIC: Final = "/tf"
LOG_TOPIC: Final = "/autopilot/log"
HEALTH_TOPIC: Final = "/autopilot/health"
# The frames of the 3D scene: the odometry's origin, the robot's body, its camera (optical:
# z ahead, x right, y down).
ODOM: Final = "odom"
BASE_LINK: Final = "base_link"
CAMERA: Final = "camera"
# base_link → camera: a robot description has no camera placement, so the camera sits at the
# body's origin, looking ahead (the optical frame's z along base_link's x).
CAMERA_ROTATION: Final = (-0.5, 0.5, -0.5, 0.5)
# Messages queued per viewer before its oldest are dropped: a few frames' worth of every channel.
BACKLOG: Final = 64
JPEG_QUALITY: Final = 80
# The image encoder thread's niceness (Linux gives each thread its own).
ENCODER_NICENESS: Final = 10
# Colours (RGBA 0-1) of the annotations: the target's box and point, and the label's text; the
# target the operator locked on is drawn in its own colour.
TARGET_COLOUR: Final = (0.0, 1.0, 0.0, 1.0)
LOCKED_COLOUR: Final = (1.0, 0.5, 0.0, 1.0)
LABEL_BACKGROUND: Final = (0.0, 0.0, 0.0, 0.6)
NO_FILL: Final = (0.0, 0.0, 0.0, 0.0)
POINT_DIAMETER_PX: Final = 8.0
# The typed channels: the SDK's channel and message classes of each (their schemas are the SDK's).
TYPED_CHANNELS: Final[dict[str, tuple[type[Any], type[Any]]]] = {
    ANNOTATIONS_TOPIC: (fc.ImageAnnotationsChannel, fm.ImageAnnotations),
    CALIBRATION_TOPIC: (fc.CameraCalibrationChannel, fm.CameraCalibration),
    POSE_TOPIC: (fc.PoseInFrameChannel, fm.PoseInFrame),
    TF_TOPIC: (fc.FrameTransformsChannel, fm.FrameTransforms),
    LOG_TOPIC: (fc.LogChannel, fm.Log),
}
_STAMP: Final = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
}
HEALTH_SCHEMA: Final[dict[str, Any]] = {
    "title": "autopilot.Health",
    "type": "object",
    "properties": {
        "timestamp": _STAMP,
        "link": {
            "type": "string",
            "enum": ["none", *get_args(ev.LinkState)],
            "description": "the link to the relay",
        },
        "relay": {"type": ["string", "null"]},
        "selected": {"type": ["string", "null"], "description": "the ICE candidate type used"},
        "goal_age_ms": {"type": ["number", "null"], "description": "since the last goal"},
        "twist_age_ms": {"type": ["number", "null"], "description": "since the last Twist"},
        "camera_fps": {"type": "number", "description": "frames sent over the last second"},
    },
}
# The JSON channels beside the typed ones: the flight recording's and the health.
JSON_SCHEMAS: Final[dict[str, dict[str, Any]]] = {
    **{topic: schema for topic, schema in recording.channels() if topic != IMAGE_TOPIC},
    HEALTH_TOPIC: HEALTH_SCHEMA,
}


def recorded_channels() -> list[ExtraChannel]:
    """The channels the flight recorder adds for Foxglove: the typed ones (protobuf, the SDK's
    schemas, as served live) and the health (JSON); the rest it records already."""
    schemas = {topic: message.get_schema() for topic, (_, message) in TYPED_CHANNELS.items()}
    typed = [
        ExtraChannel(topic, schema.name, schema.encoding, schema.data, "protobuf")
        for topic, schema in schemas.items()
    ]
    schema = json.dumps(HEALTH_SCHEMA).encode()
    health = ExtraChannel(HEALTH_TOPIC, HEALTH_SCHEMA["title"], "jsonschema", schema, "json")
    return [*typed, health]


def recording_scene(flight: FlightRecorder, robot: Robot) -> Scene:
    """The scene's every message into ``flight`` (made with :func:`recorded_channels`)."""
    return Scene(robot, flight.record, lambda topic: True)


# Where a message goes: its topic, its log time (Unix ns) and the message (an SDK message, or a
# JSON object for a JSON channel).
Emit = Callable[[str, int, Any], None]


@dataclass(frozen=True)
class Address:
    """Where the Foxglove server listens."""

    host: str
    port: int

    @property
    def loopback(self) -> bool:
        """True when only this machine can reach it."""
        if self.host == "localhost":
            return True
        try:
            return ipaddress.ip_address(self.host).is_loopback
        except ValueError:
            return False


def address(text: str) -> Address:
    """``[HOST:]PORT`` (``[::1]:PORT`` for an IPv6 host); the host is 127.0.0.1 without one. Port
    0 lets the system choose (the agent logs the one it got)."""
    host, sep, port_text = text.rpartition(":")
    host = host.removeprefix("[").removesuffix("]") if sep else DEFAULT_HOST
    if sep and not host:
        raise argparse.ArgumentTypeError(f"expected [HOST:]PORT, not {text!r}")
    number = 0 if port_text == "0" else port(port_text)
    return Address(host, number)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--foxglove [HOST:]PORT`` and its TLS files (``autopilot vehicle``)."""
    group = parser.add_argument_group("Foxglove")
    group.add_argument(
        "--foxglove",
        type=address,
        metavar="[HOST:]PORT",
        help=f"serve the camera, detections, goals, Twists, pose and events to Foxglove here"
        f" (host {DEFAULT_HOST} unless given; port {DEFAULT_PORT} is Foxglove's usual)",
    )
    group.add_argument(
        "--foxglove-certfile", type=Path, metavar="PEM", help="serve Foxglove over wss:// with it"
    )
    group.add_argument(
        "--foxglove-keyfile", type=Path, metavar="PEM", help="the PKCS#8 key of the certfile"
    )


def exposure_error(where: Address, secret_set: bool, tls: bool) -> str | None:
    """Why the Foxglove server must not start at ``where``, or None. The server asks for tokens
    (``secret_set``): a viewer on the network then shows one too, and only over TLS, where the
    token and the camera do not cross the network in clear."""
    if where.loopback or not secret_set or tls:
        return None
    return (
        f"--foxglove {where.host}:{where.port}: AUTOPILOT_SECRET is set, so a viewer on the "
        f"network must show a token, over TLS: give --foxglove-certfile PEM and "
        f"--foxglove-keyfile PEM (or serve on 127.0.0.1 and reach it through an SSH tunnel; "
        f"docs/foxglove.md)"
    )


def url(scheme: str, host: str, port: int) -> str:
    """``scheme://host:port`` (an IPv6 host in brackets)."""
    return f"{scheme}://[{host}]:{port}" if ":" in host else f"{scheme}://{host}:{port}"


def wall_ns(t: float) -> int:
    """The Unix time (ns) of ``t`` on the monotonic clock (the events' clock)."""
    return time.time_ns() - int((time.monotonic() - t) * 1e9)


def timestamp(ns: int) -> fm.Timestamp:
    """``ns`` as a Foxglove timestamp."""
    return fm.Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _stamp(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _colour(rgba: tuple[float, float, float, float]) -> fm.Color:
    r, g, b, a = rgba
    return fm.Color(r=r, g=g, b=b, a=a)


def _yaw(theta: float) -> fm.Quaternion:
    return fm.Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


def image_annotations(
    goal: ev.GoalApplied, size: tuple[int, int], stamp_ns: int
) -> fm.ImageAnnotations:
    """``goal``'s detection on an image of ``size`` (the goal's frame may be another size): the
    target's box (clipped to the image), its point and a label, in :data:`LOCKED_COLOUR` when
    the operator locked on it."""
    width, height = size
    sx, sy = width / goal.w, height / goal.h
    x, y = goal.x * sx, goal.y * sy
    stamp = timestamp(stamp_ns)
    colour = _colour(LOCKED_COLOUR if goal.locked else TARGET_COLOUR)
    points: list[fm.PointsAnnotation] = []
    top = y
    if goal.box_w is not None and goal.box_h is not None:
        half_w, half_h = goal.box_w * sx / 2, goal.box_h * sy / 2
        left, right = max(0.0, x - half_w), min(float(width), x + half_w)
        top, bottom = max(0.0, y - half_h), min(float(height), y + half_h)
        corners = [(left, top), (right, top), (right, bottom), (left, bottom)]
        points.append(
            fm.PointsAnnotation(
                timestamp=stamp,
                type=fm.PointsAnnotationType.LineLoop,
                points=[fm.Point2(x=px, y=py) for px, py in corners],
                outline_color=colour,
                outline_colors=[],
                fill_color=_colour(NO_FILL),
                thickness=2.0,
            )
        )
    return fm.ImageAnnotations(
        timestamp=stamp,
        circles=[
            fm.CircleAnnotation(
                timestamp=stamp,
                position=fm.Point2(x=x, y=y),
                diameter=POINT_DIAMETER_PX,
                thickness=2.0,
                fill_color=colour,
                outline_color=colour,
            )
        ],
        points=points,
        texts=[
            fm.TextAnnotation(
                timestamp=stamp,
                position=fm.Point2(x=min(max(0.0, x), width - 1.0), y=top),
                text=f"{goal.op} #{goal.seq}" + (" locked" if goal.locked else ""),
                font_size=14.0,
                text_color=colour,
                background_color=_colour(LABEL_BACKGROUND),
            )
        ],
    )


def calibration(hfov_deg: float, size: tuple[int, int], stamp_ns: int) -> fm.CameraCalibration:
    """A pinhole camera ``hfov_deg`` across an image of ``size``, square pixels, no distortion."""
    width, height = size
    focal = (width / 2) / math.tan(math.radians(hfov_deg) / 2)
    cx, cy = width / 2, height / 2
    return fm.CameraCalibration(
        timestamp=timestamp(stamp_ns),
        frame_id=CAMERA,
        width=width,
        height=height,
        distortion_model="plumb_bob",
        D=[0.0] * 5,
        K=[focal, 0.0, cx, 0.0, focal, cy, 0.0, 0.0, 1.0],
        R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        P=[focal, 0.0, cx, 0.0, 0.0, focal, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
    )


def pose_in_frame(pose: ev.PoseReport, stamp_ns: int) -> fm.PoseInFrame:
    """The robot's pose in ``odom``."""
    return fm.PoseInFrame(
        timestamp=timestamp(stamp_ns),
        frame_id=ODOM,
        pose=fm.Pose(position=fm.Vector3(x=pose.x, y=pose.y, z=0.0), orientation=_yaw(pose.theta)),
    )


def transforms(pose: ev.PoseReport, stamp_ns: int) -> fm.FrameTransforms:
    """``odom`` → ``base_link`` (the pose) and ``base_link`` → ``camera``."""
    stamp = timestamp(stamp_ns)
    qx, qy, qz, qw = CAMERA_ROTATION
    return fm.FrameTransforms(
        transforms=[
            fm.FrameTransform(
                timestamp=stamp,
                parent_frame_id=ODOM,
                child_frame_id=BASE_LINK,
                translation=fm.Vector3(x=pose.x, y=pose.y, z=0.0),
                rotation=_yaw(pose.theta),
            ),
            fm.FrameTransform(
                timestamp=stamp,
                parent_frame_id=BASE_LINK,
                child_frame_id=CAMERA,
                translation=fm.Vector3(x=0.0, y=0.0, z=0.0),
                rotation=fm.Quaternion(x=qx, y=qy, z=qz, w=qw),
            ),
        ]
    )


def _link_line(event: ev.LinkChanged) -> str:
    reason = f": {event.reason}" if event.reason else ""
    return f"link to {event.relay} {event.state}{reason}"


def _mode_line(event: ev.ModeChanged) -> str:
    return f"mode {event.mode}" + (f" by {event.operator}" if event.operator else "")


def _spawn_line(event: ev.SpawnStep) -> str:
    return "spawn step done" if event.ok else f"spawn step failed: {event.reason}"


# The pilot's events the log channel says, in words, and at which level.
_LOG_LINES: Final[dict[type[ev.Event], Callable[[Any], tuple[fm.LogLevel, str]]]] = {
    ev.ModeChanged: lambda e: (fm.LogLevel.Info, _mode_line(e)),
    ev.SearchStarted: lambda e: (fm.LogLevel.Info, f"target lost: searching to the {e.side}"),
    ev.SearchEnded: lambda e: (
        fm.LogLevel.Warning if e.why == "timed_out" else fm.LogLevel.Info,
        f"search ended after {e.after_s:.1f} s: {e.why}",
    ),
    ev.LinkChanged: lambda e: (
        fm.LogLevel.Warning if e.state == "down" else fm.LogLevel.Info,
        _link_line(e),
    ),
    ev.SpawnStep: lambda e: (fm.LogLevel.Info if e.ok else fm.LogLevel.Warning, _spawn_line(e)),
}


def log_message(event: ev.Event, stamp_ns: int) -> fm.Log | None:
    """``event`` as a Log line, None for a kind the log does not say."""
    line = _LOG_LINES.get(type(event))
    if line is None:
        return None
    level, text = line(event)
    return fm.Log(
        timestamp=timestamp(stamp_ns), level=level, message=text, name=f"autopilot.{event.kind}"
    )


class Scene:
    """The agent's events as Foxglove's messages, handed to ``emit`` for the topics ``wants``
    (an event-log listener; :attr:`image_size` is set by whoever sees the camera's frames)."""

    def __init__(self, robot: Robot, emit: Emit, wants: Callable[[str], bool]) -> None:
        self.robot = robot
        self.image_size: tuple[int, int] | None = None
        self._emit = emit
        self._wants = wants
        self.frame_times = FrameTimes()
        self._link: ev.LinkChanged | None = None
        self._last_goal: float | None = None
        self._last_twist: float | None = None
        self._frames: collections.deque[float] = collections.deque()

    def stamp_ns(self, frame: int | None, t: float) -> int:
        """The capture time (Unix ns) of camera frame ``frame``, else of ``t`` (monotonic s)."""
        captured = self.frame_times.captured_at(frame)
        return wall_ns(t if captured is None else captured)

    def on_event(self, event: ev.AnyEvent) -> None:
        """Emit what ``event`` shows."""
        if isinstance(event, ev.FrameSent):
            self.frame_times.add(event.frame, event.t)
            self._frames.append(event.t)
            while self._frames[0] < event.t - 1.0:
                self._frames.popleft()
        elif isinstance(event, ev.GoalApplied):
            self._last_goal = event.t
            # The camera's size until a frame says: the goal's frame's (the recorder's case).
            self.image_size = self.image_size or (round(event.w), round(event.h))
            if self._wants(ANNOTATIONS_TOPIC):
                size = self.image_size
                stamp = self.stamp_ns(event.frame, event.t)
                self._emit(ANNOTATIONS_TOPIC, stamp, image_annotations(event, size, stamp))
        elif isinstance(event, ev.TwistSent):
            self._last_twist = event.t
        elif isinstance(event, ev.PoseReport):
            self._on_pose(event)
        elif isinstance(event, ev.LinkChanged):
            self._link = event
        if type(event) in _LOG_LINES and self._wants(LOG_TOPIC):
            stamp = wall_ns(event.t)
            self._emit(LOG_TOPIC, stamp, log_message(event, stamp))

    def _on_pose(self, pose: ev.PoseReport) -> None:
        stamp = wall_ns(pose.t)
        if self._wants(POSE_TOPIC):
            self._emit(POSE_TOPIC, stamp, pose_in_frame(pose, stamp))
        if self._wants(TF_TOPIC):
            self._emit(TF_TOPIC, stamp, transforms(pose, stamp))
        camera = self.robot.camera
        size = self.image_size
        if camera is not None and size is not None and self._wants(CALIBRATION_TOPIC):
            self._emit(CALIBRATION_TOPIC, stamp, calibration(camera.hfov_deg, size, stamp))
        if self._wants(HEALTH_TOPIC):
            self._emit(HEALTH_TOPIC, stamp, self._health(pose.t, stamp))

    def _health(self, now: float, stamp_ns: int) -> dict[str, Any]:
        link = self._link

        def age(t: float | None) -> float | None:
            return None if t is None else round((now - t) * 1000, 1)

        return {
            "timestamp": _stamp(stamp_ns),
            "link": "none" if link is None else link.state,
            "relay": None if link is None else link.relay,
            "selected": None if link is None else link.selected,
            "goal_age_ms": age(self._last_goal),
            "twist_age_ms": age(self._last_twist),
            "camera_fps": float(sum(1 for t in self._frames if t > now - 1.0)),
        }


class FoxgloveLive:
    """The Foxglove WebSocket server and its channels, in an SDK context of its own (so that
    ``has_sinks`` means "a viewer subscribed"); an event-log listener, and the camera's reader
    (:meth:`stream_video`)."""

    def __init__(
        self,
        where: Address,
        robot: Robot,
        tls: tuple[bytes, bytes] | None = None,
        jpeg_quality: int = JPEG_QUALITY,
    ) -> None:
        """Start serving; OSError when the address cannot be bound."""
        self.context = foxglove.Context()
        cert, key = tls if tls is not None else (None, None)
        try:
            self.server = foxglove.start_server(
                name="webrtc-autopilot vehicle",
                host=where.host,
                port=where.port,
                capabilities=[],
                context=self.context,
                message_backlog_size=BACKLOG,
                tls_cert=cert,
                tls_key=key,
            )
        except RuntimeError as exc:  # the SDK's bind and TLS failures
            raise OSError(f"cannot serve Foxglove on {where.host}:{where.port}: {exc}") from exc
        # The SDK's server's own address; the view's (:attr:`url`) unless a gate is in front.
        self.server_url = url("wss" if tls else "ws", where.host, self.server.port)
        self.url = self.server_url
        # The token gate in front, when viewers come from the network (:meth:`put_behind`).
        self.gate: FoxgloveGate | None = None
        self.jpeg_quality = jpeg_quality
        self.images = 0
        # CPU seconds the agent's loop spent here (thread-time deltas around this view's work):
        # what viewers cost the loop, measured directly (``autopilot bench --foxglove``).
        self.loop_cpu_s = 0.0
        self._image = fc.CompressedImageChannel(IMAGE_TOPIC, context=self.context)
        self._typed = {t: cls(t, context=self.context) for t, (cls, _) in TYPED_CHANNELS.items()}
        self._json = {
            t: foxglove.Channel(t, schema=s, context=self.context) for t, s in JSON_SCHEMAS.items()
        }
        self.scene = Scene(robot, self._log, self._wants)
        # The newest camera frame not yet encoded (the encoder thread takes it); older ones are
        # replaced, never queued.
        self._latest: av.VideoFrame | None = None
        self._wake = threading.Condition()
        self._stopping = False
        self._encoder = threading.Thread(target=self._encode_all, name="foxglove-images")
        self._encoder.start()

    def _wants(self, topic: str) -> bool:
        channel = self._typed.get(topic) or self._json[topic]
        return bool(channel.has_sinks())

    def _log(self, topic: str, log_ns: int, message: Any) -> None:
        channel = self._typed.get(topic) or self._json[topic]
        channel.log(message, log_time=log_ns)

    def on_event(self, event: ev.AnyEvent) -> None:
        """Serve what ``event`` shows: the scene's messages, and the event on its recorded
        topic, stamped with its frame's capture time when it names one."""
        started = time.thread_time()
        self.scene.on_event(event)
        recorded = recording.EVENT_CHANNELS.get(type(event))
        if recorded is not None and self._json[recorded.topic].has_sinks():
            stamp = self.scene.stamp_ns(getattr(event, "frame", None), event.t)
            self._json[recorded.topic].log(recording.message(event), log_time=stamp)
        self.loop_cpu_s += time.thread_time() - started

    async def stream_video(self, track: MediaStreamTrack) -> None:
        """Hand ``track``'s newest frame to the encoder while a viewer watches the camera, until
        cancelled or the track ends."""
        try:
            while True:
                frame = await track.recv()
                if not isinstance(frame, av.VideoFrame):
                    continue
                started = time.thread_time()
                self.scene.image_size = (frame.width, frame.height)
                if self._image.has_sinks():
                    with self._wake:
                        self._latest = frame
                        self._wake.notify()
                self.loop_cpu_s += time.thread_time() - started
        except Exception as exc:  # MediaStreamError and whatever the source raises
            log.info("Foxglove's camera stopped: %s", exc or type(exc).__name__)

    def _encode_all(self) -> None:
        # Below the agent's loop when the cores are busy: the view may lag, the robot may not.
        with contextlib.suppress(OSError):
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), ENCODER_NICENESS)
        while True:
            with self._wake:
                while self._latest is None and not self._stopping:
                    self._wake.wait()
                if self._stopping:
                    return
                frame, self._latest = self._latest, None
            assert frame is not None
            try:
                stamp = self.scene.stamp_ns(frame_tag(frame), time.monotonic())
                data = encode_jpeg(frame, self.jpeg_quality)
            except Exception:
                log.exception("Foxglove's camera image failed; skipping the frame")
                continue
            image = fm.CompressedImage(
                timestamp=timestamp(stamp), frame_id=CAMERA, data=data, format="jpeg"
            )
            self._image.log(image, log_time=stamp)
            self.images += 1

    def put_behind(self, gate: FoxgloveGate, host: str) -> None:
        """Serve viewers through ``gate`` (listening on ``host``) from now on: its URL is the
        view's, and :meth:`close` closes it first."""
        self.gate = gate
        self.url = url("wss", host, gate.port) + "/"

    def close(self) -> None:
        """Stop serving (the gate first) and stop the encoder."""
        if self.gate is not None:
            self.gate.close()
        with self._wake:
            self._stopping = True
            self._wake.notify()
        self._encoder.join()
        self.server.stop()


def start(
    args: argparse.Namespace, robot: Robot, secret: str | None, room: str
) -> FoxgloveLive | None:
    """The server ``--foxglove`` asks for (None without it); OSError when it must not or cannot
    start (:func:`exposure_error`, unreadable TLS files, a port taken). With ``secret`` (the
    server's, ``AUTOPILOT_SECRET``) and a host other than this machine, the SDK's server listens
    on 127.0.0.1 behind a token gate for ``room`` (:mod:`vehicle_agent.foxglove_gate`)."""
    where: Address | None = args.foxglove
    if where is None:
        return None
    certfile, keyfile = args.foxglove_certfile, args.foxglove_keyfile
    if (certfile is None) != (keyfile is None):
        raise OSError("--foxglove-certfile and --foxglove-keyfile go together")
    refused = exposure_error(where, bool(secret), certfile is not None)
    if refused is not None:
        raise OSError(refused)
    if secret and not where.loopback:
        return _start_gated(where, robot, secret, room, certfile, keyfile)
    tls = None if certfile is None else (certfile.read_bytes(), keyfile.read_bytes())
    live = FoxgloveLive(where, robot, tls)
    if where.loopback:
        log.info("Foxglove: %s (this machine only; --foxglove HOST:PORT serves others)", live.url)
    else:
        log.warning(
            "Foxglove: %s, open to anyone who reaches it (no AUTOPILOT_SECRET, so no token is"
            " asked; see docs/foxglove.md)",
            live.url,
        )
    return live


def _start_gated(
    where: Address, robot: Robot, secret: str, room: str, certfile: Path, keyfile: Path
) -> FoxgloveLive:
    try:
        tokens.check_secret(secret)
    except ValueError as exc:
        raise OSError(f"{tokens.SECRET_ENV}: {exc}") from exc
    tls = server_tls(certfile, keyfile)
    live = FoxgloveLive(Address(DEFAULT_HOST, 0), robot)
    try:
        gate = FoxgloveGate(where.host, where.port, live.url, tls, secret, room)
    except OSError:
        live.close()
        raise
    live.put_behind(gate, where.host)
    log.warning(
        "Foxglove: %s?token=TOKEN, for viewers with a token of room %r (autopilot token --role"
        " client --room %s); the SDK's server listens on %s behind it",
        live.url, room, room, live.server_url,
    )  # fmt: skip
    return live


async def close(live: FoxgloveLive) -> None:
    """Stop ``live`` without blocking the loop on its threads."""
    await asyncio.to_thread(live.close)
