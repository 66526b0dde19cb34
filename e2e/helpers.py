"""Helpers for the end-to-end tests: the fake camera video and the simulated turtle's state."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import cv2.data
import httpx
import numpy as np
import numpy.typing as npt
from playwright.sync_api import Page

from app.server.serve import RunningServer

FACES = Path(__file__).resolve().parents[1] / "tests" / "data" / "faces"

WIDTH, HEIGHT, FPS = 640, 480, 15

Image = npt.NDArray[np.uint8]


def face_crop(image: Image) -> Image:
    """The largest frontal face of ``image`` with a margin, so the pasted face is big enough."""
    gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    cascade = cv2.CascadeClassifier(
        str(Path(cv2.data.haarcascades) / "haarcascade_frontalface_default.xml")
    )
    faces = cascade.detectMultiScale(gray, scaleFactor=1.1, minNeighbors=5)
    assert len(faces) > 0, "the source image has no detectable face"
    x, y, w, h = max(faces, key=lambda f: int(f[2]) * int(f[3]))
    m = w // 3
    top, left = max(0, y - m), max(0, x - m)
    return image[top : y + h + m, left : x + w + m]


def face_frame(face_image: Path, side: str) -> Image:
    """A plain grey 640×480 frame with the face centred in the ``side`` third."""
    frame = np.full((HEIGHT, WIDTH, 3), 110, np.uint8)
    source = cv2.imread(str(face_image))
    assert source is not None, f"cannot read {face_image}"
    face = face_crop(np.asarray(source, np.uint8))
    size = 200
    face = np.asarray(cv2.resize(face, (size, size * face.shape[0] // face.shape[1])), np.uint8)
    fh, fw = face.shape[:2]
    cx = {"left": WIDTH // 6, "right": WIDTH * 5 // 6}[side]
    x0, y0 = cx - fw // 2, HEIGHT // 2 - fh // 2
    frame[y0 : y0 + fh, x0 : x0 + fw] = face
    return frame


def write_y4m(path: Path, frame_bgr: Image, frames: int) -> None:
    """A 4:2:0 YUV4MPEG2 file of ``frames`` copies of one frame (Chromium loops it)."""
    yuv = cv2.cvtColor(frame_bgr, cv2.COLOR_BGR2YUV_I420)
    with path.open("wb") as out:
        out.write(f"YUV4MPEG2 W{WIDTH} H{HEIGHT} F{FPS}:1 Ip A1:1 C420jpeg\n".encode())
        for _ in range(frames):
            out.write(b"FRAME\n")
            out.write(yuv.tobytes())


def turtle_state(server: RunningServer, name: str = "turtle1") -> dict[str, Any]:
    """The simulated turtle's pose from ``GET /turtlesim/state``."""
    state = httpx.get(f"{server.url}/turtlesim/state", timeout=10).json()
    turtle: dict[str, Any] = next(t for t in state["turtles"] if t["name"] == name)
    return turtle


def wait_until(predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Poll ``predicate`` until it holds; fail naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")
        time.sleep(0.1)


VIDEO = "document.querySelector('[data-testid=video]')"


def wait_for_live_video(page: Page, timeout_ms: float = 90_000) -> None:
    """The page's video shows frames (videoWidth > 0) and keeps playing: currentTime advances
    and new frames are presented (a frozen picture would keep the frame count still)."""
    page.wait_for_function(f"() => {VIDEO}.videoWidth > 0", timeout=timeout_ms)
    start = page.evaluate(
        f"() => [{VIDEO}.currentTime, {VIDEO}.getVideoPlaybackQuality().totalVideoFrames]"
    )
    page.wait_for_function(
        f"""([time, frames]) => {VIDEO}.currentTime > time + 0.5
              && {VIDEO}.getVideoPlaybackQuality().totalVideoFrames >= frames + 5""",
        arg=start,
        timeout=timeout_ms,
    )


def status(page: Page) -> dict[str, Any]:
    """The page's read-only ``window.autopilotStatus``."""
    result: dict[str, Any] = page.evaluate("() => structuredClone(window.autopilotStatus)")
    return result
