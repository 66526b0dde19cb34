"""``--video ros:TOPIC``: the robot's own camera, from its topic through rosbridge.

:class:`RosCamera` is a video track like the synthetic scene: paced at ``fps``
(:class:`~vehicle_agent.video.PacedVideoTrack`), every frame stamped with its number (the frame
tag, :mod:`app.protocol.frametag`) and reported as a :class:`~app.protocol.events.FrameSent`
whose time is when the picture was taken, so latency is still measured from the camera on. Its
pictures come from ``sensor_msgs/CompressedImage`` or ``sensor_msgs/Image`` messages
(:mod:`app.protocol.camera`, :mod:`vehicle_agent.rosimage`) over the agent's one rosbridge
connection, the robot link's, in CBOR where the server offers it
(:mod:`vehicle_agent.rosbridge_client`).

* **Latest wins.** Messages are kept in a one-place slot (:class:`LatestSlot`): a newer one
  replaces the one waiting, which is dropped and counted, and only the one a frame takes is
  decoded. A consumer slower than the camera gets the newest picture, never a backlog; a camera
  slower than ``fps`` has its newest picture sent again (a new frame number, the same time).
* **Fitted.** Every picture is letterboxed into ``size`` (the protocol's 640×480 unless told):
  the encoder sees one size whatever the camera sends.
* **Capture time.** The message's header stamp when it is believable (:func:`capture_time`),
  else the time it arrived; the event's ``capture`` says which.
* **No camera.** Before the first picture, and once none came for :data:`SILENT_AFTER_S`, the
  track sends a plain "no camera" frame instead of a frozen old one: the relay finds nothing in
  it, so the vehicle stops on its goal timeout. Each change is said once in the log.
* **Bad messages** (a wrong encoding, truncated or corrupt data, wrong sizes, not base64) are
  skipped; each sort is logged once and all are counted.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, Generic, TypeVar

import av
import cv2
import numpy as np

from app.protocol import frametag
from app.protocol.camera import (
    CameraMessageError,
    CameraType,
    CameraTypeError,
    choose_type,
    parse,
)
from app.protocol.events import CaptureClock, FrameSent
from app.protocol.robot import Robot
from app.protocol.video import VIDEO_FPS, VIDEO_SIZE
from vehicle_agent.rosbridge_client import (
    CBOR,
    NONE,
    Compression,
    Publication,
    RosbridgeClient,
    RosbridgeError,
    StatusOp,
    Subscription,
)
from vehicle_agent.rosimage import ImageProblem, Pixels, fit, letterbox, to_rgb
from vehicle_agent.video import PacedVideoTrack, VideoSourceError

log = logging.getLogger(__name__)

# The --video prefix of a camera topic: ros:/camera/image/compressed.
ROS_PREFIX: Final = "ros:"
# ``--video ros``: the camera topic the robot's description names.
ROS_SOURCE: Final = "ros"
# With no new picture for this long the camera is silent: "no camera" frames from then on. Half
# a second is 15 frames of a 30 fps camera, and well inside the default goal timeout, so a
# vehicle whose camera stops stops soon after.
SILENT_AFTER_S: Final = 0.5
# A header stamp older than this on arrival is not believed (a robot's clock set differently,
# sim time): the receipt time stands in.
MAX_STAMP_AGE_S: Final = 2.0
# The "no camera" frame: dark grey, its words in a lighter grey (no colour or face for any
# operation to find).
_BLANK_GREY: Final = 40
_TEXT_GREY: Final = 150

T = TypeVar("T")


class CameraError(VideoSourceError):
    """The camera topic cannot be used: unreachable rosbridge, a type that is no image."""


def camera_of(source: str, robot: Robot) -> tuple[str, CameraType | None] | None:
    """The camera topic of a ``--video`` value, and its type where ``robot``'s description
    names it; None for a source that is not a ROS topic.

    ``ros:TOPIC`` names the topic; a bare ``ros`` is the camera ``robot`` describes. The
    description's type goes with its own topic only (any other topic's type is learnt from
    rosapi or its name)."""
    if source == ROS_SOURCE:
        if robot.camera is None:
            raise CameraError(
                f"--video ros: the robot {robot.name} has no camera topic in its description; "
                "name one: --video ros:/camera/image_raw/compressed"
            )
        return robot.camera.topic, robot.camera.type
    topic = topic_of(source)
    if topic is None:
        return None
    described = robot.camera.type if robot.camera and robot.camera.topic == topic else None
    return topic, described


def topic_of(source: str) -> str | None:
    """The topic of a ``--video ros:TOPIC`` value (None for any other source)."""
    if not source.startswith(ROS_PREFIX):
        return None
    topic = source.removeprefix(ROS_PREFIX)
    if not topic.strip("/"):
        raise CameraError(f"--video {source!r} names no topic: use ros:/camera/image/compressed")
    return topic if topic.startswith("/") else f"/{topic}"


def capture_time(stamp_s: float, at: float, wall: float) -> tuple[float, CaptureClock]:
    """When a picture stamped ``stamp_s`` (Unix s) and received at ``at`` (monotonic s) = ``wall``
    (Unix s) was taken, on the monotonic clock, and which clock says so.

    The stamp is believed when it is no later than the receipt and at most
    :data:`MAX_STAMP_AGE_S` before it; otherwise (a zero stamp, a robot whose clock differs from
    this machine's, sim time) the receipt time is all there is.
    """
    age = wall - stamp_s
    if 0.0 <= age <= MAX_STAMP_AGE_S:
        return at - age, "stamp"
    return at, "receipt"


class LatestSlot(Generic[T]):
    """A mailbox of one: :meth:`put` replaces what waits (counted in :attr:`dropped`)."""

    def __init__(self) -> None:
        self._item: T | None = None
        self.received = 0
        self.dropped = 0

    def put(self, item: T) -> None:
        """Keep ``item``; the one it replaces, if any, is dropped."""
        if self._item is not None:
            self.dropped += 1
        self._item = item
        self.received += 1

    @property
    def waiting(self) -> T | None:
        """The item a take would give now, left where it is."""
        return self._item

    def take(self) -> T | None:
        """The newest item, once (None when nothing came since the last take)."""
        item, self._item = self._item, None
        return item


@dataclass(frozen=True)
class Picture:
    """A decoded camera picture, fitted to the video: taken at ``captured`` (monotonic s, by
    ``clock``), received at ``received``; ``source`` is its size as the camera sent it."""

    pixels: Pixels
    captured: float
    clock: CaptureClock
    received: float
    source: tuple[int, int]


def blank_frame(size: tuple[int, int], topic: str) -> Pixels:
    """The "no camera" frame: plain grey, saying so."""
    width, height = size
    frame = np.full((height, width, 3), _BLANK_GREY, np.uint8)
    scale = max(0.4, width / 640)
    for row, text in enumerate(("no camera", topic)):
        cv2.putText(
            frame,
            text,
            (round(width * 0.06), round(height * (0.45 + 0.1 * row))),
            cv2.FONT_HERSHEY_SIMPLEX,
            scale * (1.0 if row == 0 else 0.6),
            (_TEXT_GREY,) * 3,
            2,
            cv2.LINE_AA,
        )
    return frame


class RosCamera(PacedVideoTrack):
    """Frames from a ROS camera topic through the rosbridge ``client`` is connected to (see the
    module docstring); the client is borrowed, the robot link's, and left open at the end.

    ``described`` is the topic's type as the robot's description names it (used when rosapi
    cannot say); ``compression`` is what to ask rosbridge for (``cbor``, falling back to JSON
    when the server refuses, or ``none``). :meth:`start` subscribes before the first frame.
    """

    def __init__(
        self,
        client: RosbridgeClient,
        topic: str,
        *,
        size: tuple[int, int] = VIDEO_SIZE,
        fps: float = VIDEO_FPS,
        described: CameraType | None = None,
        compression: Compression = CBOR,
        on_frame: Callable[[FrameSent], None] | None = None,
    ) -> None:
        super().__init__(fps)
        if size[0] < 2 * frametag.LAYOUT.blocks_per_width or size[1] < 48:
            raise CameraError(f"camera video needs at least 80x48 pixels, not {size[0]}x{size[1]}")
        self.client = client
        self.topic = topic
        self.size = size
        self.described = described
        self.compression: Compression = compression
        self.on_frame = on_frame
        self.message_type: CameraType | None = None
        self.slot: LatestSlot[Publication] = LatestSlot()
        # What happened, for tests and the summary at stop.
        self.problems: Counter[str] = Counter()
        self.pictures = 0
        self.sent = 0
        self.blanks = 0
        self.binary = 0
        self._blank = blank_frame(size, topic)
        self._picture: Picture | None = None
        self._silent_since: float | None = None
        self._subscription: Subscription | None = None
        self._said: set[str] = set()

    # -- connection ---------------------------------------------------------------------

    async def start(self) -> None:
        """Connect (unless the robot link did), learn the topic's type and subscribe;
        :class:`CameraError` if it cannot."""
        client = self.client
        try:
            await client.connect()
        except RosbridgeError as exc:
            raise CameraError(f"camera {self.topic}: {exc}") from None
        try:
            self.message_type, source = choose_type(
                self.topic, await client.topic_type(self.topic), self.described
            )
        except CameraTypeError as exc:
            raise CameraError(str(exc)) from None
        self._subscription = client.subscribe(
            self.topic,
            self.message_type,
            self._on_message,
            compression=self.compression,
            # Only the newest message matters to us, on the server's side too.
            queue_length=1,
            on_status=self._on_status,
        )
        described = {"rosapi": "the robot's rosapi", "description": "the robot's description"}
        log.info(
            "camera %s: %s (from %s), through %s; waiting for its first frame",
            self.topic,
            self.message_type,
            described.get(source, "the topic's name"),
            client.url,
        )

    def _on_message(self, publication: Publication) -> None:
        self.slot.put(publication)
        if publication.binary:
            self.binary += 1
            self._say_once("cbor", logging.INFO, "camera %s: CBOR frames", self.topic)
        elif self.compression == CBOR:
            self._say_once(
                "json", logging.INFO, "camera %s: the rosbridge sends JSON (no CBOR)", self.topic
            )

    def _on_status(self, status: StatusOp) -> None:
        subscription = self._subscription
        if status.level not in ("warning", "error") or subscription is None:
            return
        if self.compression == CBOR and self.binary == 0:
            # A rosbridge that does not know the compression: ask again without.
            log.info(
                "camera %s: the rosbridge refused CBOR (%s); JSON with base64 instead",
                self.topic,
                status.msg,
            )
            self.compression = subscription.compression = NONE
            self.client.resubscribe(subscription)
            return
        self._say_once(
            "status", logging.WARNING, "camera %s: the rosbridge says %s", self.topic, status.msg
        )

    def stop(self) -> None:
        """Stop the track and its subscription; log what the camera did."""
        was_live = self.readyState == "live"
        super().stop()
        if self._subscription is not None:
            self.client.unsubscribe(self._subscription)
            self._subscription = None
        if was_live:
            log.info(
                "camera %s: %d messages (%d dropped for newer ones, %d bad), %d frames sent "
                "with a picture, %d without",
                self.topic,
                self.slot.received,
                self.slot.dropped,
                sum(self.problems.values()),
                self.sent,
                self.blanks,
            )

    # -- frames -------------------------------------------------------------------------

    async def make_frame(self, index: int) -> av.VideoFrame:
        """The newest picture (decoded now, off the event loop) with tag ``index``, or the
        "no camera" frame."""
        pending = self.slot.take()
        if pending is not None:
            try:
                decoded = await asyncio.to_thread(self._decode, pending)
            except (CameraMessageError, ImageProblem) as exc:
                self._problem(getattr(exc, "kind", "message"), str(exc))
            else:
                self._show(decoded)
        now = time.monotonic()
        picture = self._picture
        if picture is None or now - picture.received > SILENT_AFTER_S:
            self._silence(now)
            pixels = self._blank.copy()
            frametag.stamp(pixels, index)
            self.blanks += 1
            return av.VideoFrame.from_ndarray(pixels, format="rgb24")
        pixels = picture.pixels.copy()
        frametag.stamp(pixels, index)
        self.sent += 1
        if self.on_frame is not None:
            self.on_frame(FrameSent(frame=index, capture=picture.clock, t=picture.captured))
        return av.VideoFrame.from_ndarray(pixels, format="rgb24")

    def _decode(self, publication: Publication) -> Picture:
        assert self.message_type is not None
        image = parse(self.message_type, publication.msg)
        rgb = to_rgb(image)
        captured, clock = capture_time(image.header.stamp.seconds, publication.at, publication.wall)
        height, width = rgb.shape[:2]
        return Picture(letterbox(rgb, self.size), captured, clock, publication.at, (width, height))

    def _show(self, picture: Picture) -> None:
        """A new good picture: it is what the frames show from now on."""
        self.pictures += 1
        first = self._picture is None
        self._picture = picture
        if first:
            width, height = picture.source
            placed = fit(width, height, self.size)
            log.info(
                "camera %s: first frame, %dx%d%s",
                self.topic,
                width,
                height,
                ""
                if placed.scaled == (width, height)
                else f", letterboxed into {self.size[0]}x{self.size[1]}",
            )
            if placed.scaled[0] < self.size[0]:
                log.warning(
                    "camera %s: its frames are narrower than %dx%d and sent pillarboxed: a "
                    "column's bearing no longer spans the frame's width",
                    self.topic,
                    *self.size,
                )
        self._say_once(
            picture.clock,
            logging.INFO,
            "camera %s: frame times from %s",
            self.topic,
            "the messages' header stamps"
            if picture.clock == "stamp"
            else "their arrival (header stamps missing or not believable)",
        )
        if self._silent_since is not None:
            log.info(
                "camera %s: frames again after %.1f s",
                self.topic,
                time.monotonic() - self._silent_since,
            )
            self._silent_since = None

    def _silence(self, now: float) -> None:
        if self._picture is None or self._silent_since is not None:
            return
        self._silent_since = now
        log.warning(
            "camera %s: no frame for %.1f s; sending 'no camera' frames",
            self.topic,
            SILENT_AFTER_S,
        )

    def _problem(self, kind: str, text: str) -> None:
        self.problems[kind] += 1
        self._say_once(
            f"problem:{kind}", logging.WARNING, "camera %s: skipped a message: %s", self.topic, text
        )

    def _say_once(self, key: str, level: int, message: str, *args: object) -> None:
        if key in self._said:
            return
        self._said.add(key)
        log.log(level, message, *args)
