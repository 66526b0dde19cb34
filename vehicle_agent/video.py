"""Video sources for the agent, as aiortc ``MediaStreamTrack`` subclasses.

* :class:`SyntheticVideo` -- a generated scene in which a real face photo moves along a known
  path; each frame carries its number as the frame tag (:mod:`app.protocol.frametag`), so the
  relay can read it back and echo it in its goals (latency measurement), and
  :meth:`SyntheticVideo.face_centre` tells tests and benchmarks where the face truly is.
* :class:`FileVideo` -- anything PyAV opens (``.y4m``, ``.mp4``, ...), looped forever.
* a V4L2 device (``/dev/videoN``) through aiortc's ``MediaPlayer``.

:func:`open_source` picks one from the command line's ``--video`` value.
"""

from __future__ import annotations

import asyncio
import fractions
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import av
import cv2
import cv2.data
import numpy as np
import numpy.typing as npt
from aiortc import MediaStreamTrack
from aiortc.contrib.media import MediaPlayer
from aiortc.mediastreams import MediaStreamError

from app.flame import draw_flame
from app.protocol import frametag
from app.protocol.events import FrameSent
from app.protocol.video import VIDEO_FPS, VIDEO_SIZE
from app.resources import FACES_DIR

log = logging.getLogger(__name__)

DEFAULT_FACE = FACES_DIR / "obama.jpg"
SMALL_FACE = FACES_DIR / "biden.jpg"
CLOCK_RATE = 90_000
TIME_BASE = fractions.Fraction(1, CLOCK_RATE)

Image = npt.NDArray[np.uint8]

# The --video values of the generated scenes: the moving face (SyntheticVideo) and the
# target-lock scene (TwoFaceVideo).
SYNTHETIC = "synthetic"
TWO_FACES = "two-faces"


class VideoSourceError(RuntimeError):
    """A video source could not be opened; the message names the source and the problem."""


# --- synthetic scene ---------------------------------------------------------------------


class FacePath(Protocol):
    """Where the face centre is at a given time, as fractions (0..1) of width and height."""

    def __call__(self, t: float) -> tuple[float, float]: ...

    def jumped(self, t0: float, t1: float) -> bool:
        """True when the face leapt (rather than moved) at some time in (``t0``, ``t1``]."""
        ...


@dataclass(frozen=True)
class SweepPath:
    """Glides and leaps between a left and a right spot; repeats every :attr:`cycle_s`.

    One cycle: hold on the left, glide right, hold, glide back, hold, then leap right, hold,
    and leap back left (the cycle's end). The glides test steady tracking, the leaps how soon a
    detector finds a face that jumped across the frame (:meth:`jumped` names their times).

    The face sits a little above the middle row so that, seen from the terrain centre, "left"
    and "right" are clearly ≈170° and ≈10° rather than a coin toss across ±180°.
    """

    left: float = 0.22
    right: float = 0.78
    y: float = 0.42
    hold_s: float = 4.0
    glide_s: float = 2.0

    @classmethod
    def with_cycle(cls, cycle_s: float) -> SweepPath:
        """The same sweep, played faster or slower: each hold twice as long as each glide, as in
        the default 20 s cycle (a short bench run still sees the face glide and leap)."""
        return cls(hold_s=cycle_s / 5, glide_s=cycle_s / 10)

    @property
    def cycle_s(self) -> float:
        """Length of one cycle: four holds and two glides."""
        return 4 * self.hold_s + 2 * self.glide_s

    def jump_times(self) -> tuple[float, float]:
        """Phases (s into a cycle) of the leap right and of the leap back left (the cycle end)."""
        return 3 * self.hold_s + 2 * self.glide_s, self.cycle_s

    def __call__(self, t: float) -> tuple[float, float]:
        phase = t % self.cycle_s
        span = self.right - self.left
        hold, glide = self.hold_s, self.glide_s
        if phase < hold:
            x = self.left
        elif phase < hold + glide:
            x = self.left + span * _ease((phase - hold) / glide)
        elif phase < 2 * hold + glide:
            x = self.right
        elif phase < 2 * hold + 2 * glide:
            x = self.right - span * _ease((phase - 2 * hold - glide) / glide)
        elif phase < self.jump_times()[0]:
            x = self.left
        else:
            x = self.right
        return x, self.y

    def jumped(self, t0: float, t1: float) -> bool:
        """True when a leap happened at some time in (``t0``, ``t1``]."""
        cycle = self.cycle_s
        for phase in self.jump_times():
            # The latest leap of this kind at or before t1 (none before the path starts).
            at = math.floor((t1 - phase) / cycle) * cycle + phase
            if t0 < at <= t1 and at > 0:
                return True
        return False


@dataclass
class FixedPath:
    """A face that stays where a test puts it (``x``, ``y`` may be changed at any time)."""

    x: float
    y: float

    def __call__(self, t: float) -> tuple[float, float]:
        return self.x, self.y

    def jumped(self, t0: float, t1: float) -> bool:
        """Never: a test that moves the face knows when it did."""
        return False


@dataclass
class DriftPath:
    """A face that drifts slowly around (``x``, ``y``): ``dx``, ``dy`` either way, one round in
    ``period_s``, starting ``phase`` radians in."""

    x: float
    y: float
    dx: float
    dy: float
    period_s: float
    phase: float = 0.0

    def __call__(self, t: float) -> tuple[float, float]:
        a = 2 * math.pi * t / self.period_s + self.phase
        return self.x + self.dx * math.sin(a), self.y + self.dy * math.sin(2 * a)

    def jumped(self, t0: float, t1: float) -> bool:
        """Never: it only drifts."""
        return False


def _ease(u: float) -> float:
    return 0.5 - 0.5 * math.cos(math.pi * u)


class _FaceSprite:
    """A face photo cropped around its face and scaled so the face box is ``face_px`` high."""

    def __init__(self, photo: Path, face_px: int) -> None:
        loaded = cv2.imread(str(photo))
        if loaded is None:
            raise VideoSourceError(f"cannot read face photo {photo}")
        bgr: Image = np.asarray(loaded, dtype=np.uint8)
        x, y, w, h = _find_face(bgr, photo)
        # Keep some hair and chin around the box so the cascade sees a whole face.
        margin = 0.35
        x0, y0 = max(0, int(x - margin * w)), max(0, int(y - margin * h))
        x1 = min(bgr.shape[1], int(x + (1 + margin) * w))
        y1 = min(bgr.shape[0], int(y + (1 + margin) * h))
        scale = face_px / h
        crop = cv2.cvtColor(bgr[y0:y1, x0:x1], cv2.COLOR_BGR2RGB)
        size = (max(1, round((x1 - x0) * scale)), max(1, round((y1 - y0) * scale)))
        self.image: Image = np.asarray(
            cv2.resize(crop, size, interpolation=cv2.INTER_AREA), dtype=np.uint8
        )
        # Face-box centre inside the sprite.
        self.cx = (x + w / 2 - x0) * scale
        self.cy = (y + h / 2 - y0) * scale


def _find_face(bgr: Image, photo: Path) -> tuple[int, int, int, int]:
    """The largest frontal face of the photo, found once at load time on a reduced copy."""
    reduce = max(1.0, bgr.shape[0] / 600)
    small = cv2.resize(bgr, None, fx=1 / reduce, fy=1 / reduce, interpolation=cv2.INTER_AREA)
    gray = cv2.cvtColor(small, cv2.COLOR_BGR2GRAY)
    cascade = cv2.CascadeClassifier(
        str(Path(cv2.data.haarcascades) / "haarcascade_frontalface_default.xml")
    )
    faces = cascade.detectMultiScale(gray, scaleFactor=1.1, minNeighbors=5, minSize=(40, 40))
    if len(faces) == 0:
        raise VideoSourceError(f"no face found in {photo}")
    x, y, w, h = max(faces, key=lambda f: int(f[2]) * int(f[3]))
    return (round(x * reduce), round(y * reduce), round(w * reduce), round(h * reduce))


def _background(width: int, height: int) -> Image:
    """A calm room-like scene: wall gradient, floor, a few shapes; no texture to compress."""
    rows = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None]
    wall = np.array([150, 170, 190], np.float32)
    floor = np.array([110, 95, 80], np.float32)
    horizon = int(height * 0.78)
    img = np.empty((height, width, 3), np.float32)
    img[:horizon] = wall * (0.85 + 0.15 * rows[:horizon, :, None])
    img[horizon:] = floor
    out = img.astype(np.uint8)
    # Two flat blocks, (left, top, right, bottom) as fractions of the frame, and their colours.
    blocks = (((0.05, 0.2, 0.12, 0.78), (90, 70, 60)), ((0.86, 0.25, 0.97, 0.5), (200, 210, 225)))
    for (left, top, right, bottom), colour in blocks:
        corner = (int(width * left), int(height * top))
        opposite = (int(width * right), int(height * bottom))
        cv2.rectangle(out, corner, opposite, colour, -1)
    cv2.line(out, (0, horizon), (width, horizon), (70, 60, 50), 2)
    return out


# Where the scene's flame stands, as fractions of width and height: on the floor, well below
# the face's path, so that the face and fire operations pick different targets.
DEFAULT_FLAME = (0.62, 0.86)


class PacedVideoTrack(MediaStreamTrack):
    """A video track paced at ``fps`` (aiortc's ``VideoStreamTrack.next_timestamp`` is fixed
    at 30 fps); subclasses implement :meth:`make_frame`."""

    kind = "video"

    def __init__(self, fps: float) -> None:
        super().__init__()
        if fps <= 0:
            raise VideoSourceError(f"frame rate must be positive, not {fps}")
        self.fps = fps
        self._start: float | None = None
        self._index = 0

    async def next_timestamp(self) -> tuple[int, int]:
        """Wait until the next frame is due; returns (pts in 1/90000 s, frame index)."""
        if self.readyState != "live":
            raise MediaStreamError
        now = time.monotonic()
        if self._start is None:
            self._start = now
        else:
            self._index += 1
            due = self._start + self._index / self.fps
            if due > now:
                await asyncio.sleep(due - now)
            elif now - due > 1.0:
                # Far behind (a stalled loop): restart the schedule rather than burst frames.
                self._start = now - self._index / self.fps
        return round(self._index * CLOCK_RATE / self.fps), self._index

    async def recv(self) -> av.VideoFrame:
        """The next frame, when it is due."""
        pts, index = await self.next_timestamp()
        frame = await self.make_frame(index)
        frame.pts = pts
        frame.time_base = TIME_BASE
        return frame

    async def make_frame(self, index: int) -> av.VideoFrame:
        """Produce frame number ``index``."""
        raise NotImplementedError


class SyntheticVideo(PacedVideoTrack):
    """A face photo moving over a still scene along ``path``, and a flame standing at ``flame``
    (fractions of width and height; None for none); every frame carries its tag."""

    def __init__(
        self,
        width: int = VIDEO_SIZE[0],
        height: int = VIDEO_SIZE[1],
        fps: float = VIDEO_FPS,
        path: FacePath | None = None,
        photo: Path = DEFAULT_FACE,
        on_frame: Callable[[FrameSent], None] | None = None,
        flame: tuple[float, float] | None = DEFAULT_FLAME,
    ) -> None:
        super().__init__(fps)
        if width < 2 * frametag.LAYOUT.blocks_per_width or height < 48:
            raise VideoSourceError(
                f"synthetic video needs at least 80x48 pixels, not {width}x{height}"
            )
        self.width, self.height = width, height
        self.path: FacePath = path or SweepPath()
        self.flame = flame
        self.on_frame = on_frame
        self._sprite = _FaceSprite(photo, face_px=max(24, height // 4))
        self._background = _background(width, height)

    def face_centre(self, frame: int) -> tuple[float, float]:
        """True centre (pixels) of the face box in frame number ``frame``."""
        fx, fy = self.path(frame / self.fps)
        return fx * self.width, fy * self.height

    def flame_centre(self) -> tuple[float, float] | None:
        """Centre (pixels) of the flame, or None when the scene has none."""
        if self.flame is None:
            return None
        return self.flame[0] * self.width, self.flame[1] * self.height

    def jumped(self, frame: int) -> bool:
        """True when the face leapt across the frame between frame ``frame`` − 1 and this one."""
        return frame > 0 and self.path.jumped((frame - 1) / self.fps, frame / self.fps)

    def render(self, frame: int) -> Image:
        """Frame number ``frame`` as an RGB array (H×W×3)."""
        img = self._background.copy()
        flame = self.flame_centre()
        if flame is not None:
            draw_flame(img, flame[0], flame[1], frame)
        self._paste(img, self._sprite, self.face_centre(frame))
        frametag.stamp(img, frame)
        return img

    def _paste(self, img: Image, sprite: _FaceSprite, centre: tuple[float, float]) -> None:
        """Draw ``sprite`` with its face centred on ``centre``, clipped to the frame (a path
        may take the face partly out of view)."""
        x0 = round(centre[0] - sprite.cx)
        y0 = round(centre[1] - sprite.cy)
        sh, sw = sprite.image.shape[:2]
        ix0, iy0 = max(0, x0), max(0, y0)
        ix1, iy1 = min(self.width, x0 + sw), min(self.height, y0 + sh)
        if ix1 > ix0 and iy1 > iy0:
            img[iy0:iy1, ix0:ix1] = sprite.image[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0]

    async def make_frame(self, index: int) -> av.VideoFrame:
        """Render frame ``index`` and report it to ``on_frame``."""
        frame = av.VideoFrame.from_ndarray(self.render(index), format="rgb24")
        if self.on_frame is not None:
            cx, cy = self.face_centre(index)
            self.on_frame(
                FrameSent(
                    frame=index, face_x=cx, face_y=cy, jump=self.jumped(index), t=time.monotonic()
                )
            )
        return frame


class TwoFaceVideo(SyntheticVideo):
    """The target-lock scene (docs/architecture.md, "Which target"): two faces drifting
    slowly, a large one on the left (the default choice) and one ``small_share`` its size on the
    right; no flame. The large face is :meth:`face_centre`, the small one :meth:`small_centre`.
    A third, tiny face (``tiny_share`` of the large one, :meth:`tiny_centre`) drifts up between
    them: too small for the relay's reduced-size scan to find, as a person far away is, it has no
    box until the operator clicks it (a full-resolution search around the click,
    app/protocol/lock.py)."""

    def __init__(
        self,
        width: int = VIDEO_SIZE[0],
        height: int = VIDEO_SIZE[1],
        fps: float = VIDEO_FPS,
        on_frame: Callable[[FrameSent], None] | None = None,
        small_share: float = 0.65,
        tiny_share: float = 1 / 3,
    ) -> None:
        super().__init__(
            width, height, fps, DriftPath(0.3, 0.45, 0.06, 0.04, 9.0), on_frame=on_frame, flame=None
        )
        self.small_path = DriftPath(0.72, 0.5, 0.05, 0.05, 7.0, phase=1.0)
        self.small_px = max(24, round(height // 4 * small_share))
        self._small = _FaceSprite(SMALL_FACE, face_px=self.small_px)
        self.tiny_path = DriftPath(0.62, 0.19, 0.02, 0.01, 11.0, phase=2.0)
        self.tiny_px = max(12, round(height // 4 * tiny_share))
        self._tiny = _FaceSprite(DEFAULT_FACE, face_px=self.tiny_px)

    def small_centre(self, frame: int) -> tuple[float, float]:
        """True centre (pixels) of the small face's box in frame number ``frame``."""
        fx, fy = self.small_path(frame / self.fps)
        return fx * self.width, fy * self.height

    def tiny_centre(self, frame: int) -> tuple[float, float]:
        """True centre (pixels) of the tiny face's box in frame number ``frame``."""
        fx, fy = self.tiny_path(frame / self.fps)
        return fx * self.width, fy * self.height

    def render(self, frame: int) -> Image:
        """Frame number ``frame``: the scene with its three faces, and the tag on top."""
        img = super().render(frame)
        self._paste(img, self._small, self.small_centre(frame))
        self._paste(img, self._tiny, self.tiny_centre(frame))
        frametag.stamp(img, frame)
        return img


class FileVideo(PacedVideoTrack):
    """Frames of a video file (anything PyAV opens), looped, optionally rescaled."""

    def __init__(
        self, path: Path, size: tuple[int, int] | None = None, fps: float | None = None
    ) -> None:
        self.path = path
        self.size = size
        self._container = self._open()
        stream = self._container.streams.video[0]
        rate = float(stream.average_rate) if stream.average_rate else 30.0
        super().__init__(fps or rate)
        self._frames = self._container.decode(video=0)
        # Fail now, not in the middle of a session, if the file has no decodable frame.
        try:
            self._first: av.VideoFrame | None = next(self._frames)
        except (StopIteration, av.FFmpegError) as exc:
            raise VideoSourceError(
                f"cannot decode video file {path}: {exc or 'no frames'}"
            ) from exc

    def _open(self) -> av.container.InputContainer:
        try:
            container = av.open(str(self.path))
        except (OSError, av.FFmpegError) as exc:
            raise VideoSourceError(f"cannot open video file {self.path}: {exc}") from exc
        if not container.streams.video:
            container.close()
            raise VideoSourceError(f"video file {self.path} has no video stream")
        return container

    def _next_decoded(self) -> av.VideoFrame:
        if self._first is not None:
            frame, self._first = self._first, None
            return frame
        try:
            return next(self._frames)
        except StopIteration:
            # End of file: start again from the beginning (reopening works for every format,
            # seeking does not, e.g. for .y4m pipes).
            self._container.close()
            self._container = self._open()
            self._frames = self._container.decode(video=0)
            return next(self._frames)

    def _next_frame(self) -> av.VideoFrame:
        frame = self._next_decoded()
        if self.size is not None and (frame.width, frame.height) != self.size:
            frame = frame.reformat(width=self.size[0], height=self.size[1])
        return frame

    async def make_frame(self, index: int) -> av.VideoFrame:
        """Decode the next frame off the event loop."""
        return await asyncio.to_thread(self._next_frame)

    def stop(self) -> None:
        """Stop the track and close the file."""
        super().stop()
        self._container.close()


def open_device(device: str, size: tuple[int, int] | None, fps: float | None) -> MediaStreamTrack:
    """A V4L2 camera through aiortc's ``MediaPlayer``."""
    if not Path(device).exists():
        raise VideoSourceError(f"no such video device: {device}")
    options: dict[str, str] = {}
    if size is not None:
        options["video_size"] = f"{size[0]}x{size[1]}"
    if fps is not None:
        options["framerate"] = f"{fps:g}"
    try:
        player = MediaPlayer(device, format="v4l2", options=options)
    except (OSError, av.FFmpegError) as exc:
        raise VideoSourceError(f"cannot open video device {device}: {exc}") from exc
    if player.video is None:
        raise VideoSourceError(f"video device {device} gives no video")
    track: MediaStreamTrack = player.video
    return track


def open_source(
    source: str,
    size: tuple[int, int] | None = None,
    fps: float | None = None,
    on_frame: Callable[[FrameSent], None] | None = None,
    sweep_s: float | None = None,
) -> MediaStreamTrack:
    """The track for a ``--video`` value: ``synthetic``, ``two-faces``, ``/dev/videoN`` or a
    file path; ``sweep_s``: the synthetic face's cycle (default :class:`SweepPath`'s)."""
    if source == SYNTHETIC:
        width, height = size or VIDEO_SIZE
        sweep = None if sweep_s is None else SweepPath.with_cycle(sweep_s)
        return SyntheticVideo(width, height, fps or VIDEO_FPS, path=sweep, on_frame=on_frame)
    if source == TWO_FACES:
        width, height = size or VIDEO_SIZE
        return TwoFaceVideo(width, height, fps or VIDEO_FPS, on_frame=on_frame)
    if source.startswith("/dev/video"):
        return open_device(source, size, fps)
    path = Path(source)
    if not path.is_file():
        raise VideoSourceError(f"no such video file: {source}")
    return FileVideo(path, size, fps)
