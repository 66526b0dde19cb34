"""Helpers for the end-to-end tests: the fake camera video and the simulated turtle's state."""

from __future__ import annotations

import math
import ssl
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np
import numpy.typing as npt
from playwright.sync_api import Browser, CDPSession, Page

from app.protocol.angles import wrap_angle
from app.server.serve import RunningServer
from tests.helpers import waiting
from tests.vision.frames import face_crop

WIDTH, HEIGHT, FPS = 640, 480, 15

Image = npt.NDArray[np.uint8]


def face_frame(face_image: str, side: str) -> Image:
    """A plain grey 640×480 frame with the face of ``face_image`` (in tests/data/faces) centred
    in the ``side`` third."""
    frame = np.full((HEIGHT, WIDTH, 3), 110, np.uint8)
    face = face_crop(face_image)
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


def turtle_state(
    server: RunningServer,
    name: str = "turtle1",
    *,
    token: str | None = None,
    ca_file: Path | None = None,
) -> dict[str, Any]:
    """The simulated turtle's pose from ``GET /turtlesim/state``; over HTTPS, ``ca_file`` is the
    CA to verify the server with, and ``token`` the bearer token a guarded server asks for."""
    response = httpx.get(
        f"{server.url}/turtlesim/state",
        headers={} if token is None else {"Authorization": f"Bearer {token}"},
        verify=True if ca_file is None else ssl.create_default_context(cafile=str(ca_file)),
        timeout=10,
    )
    response.raise_for_status()
    turtle: dict[str, Any] = next(t for t in response.json()["turtles"] if t["name"] == name)
    return turtle


def theta(server: RunningServer) -> float:
    """The simulated turtle1's heading."""
    return float(turtle_state(server)["theta"])


def ccw_from(start: float, now: float) -> float:
    """How far a heading turned counter-clockwise from ``start`` to ``now``, in (−π, π]."""
    return math.remainder(now - start, 2 * math.pi)


def stopped(vehicle: Page) -> bool:
    """The vehicle page's last published Twist is the zero Twist."""
    twist: dict[str, Any] | None = status(vehicle)["lastTwist"]
    return twist is not None and twist["linear"] == 0 and twist["angular"] == 0


def heading_error(theta: float, goal: float) -> float:
    """Absolute angle between two headings, in [0, π]."""
    return abs(wrap_angle(theta - goal))


def wait_until(predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Poll ``predicate`` until it holds; fail naming ``what`` after ``timeout_s``.

    Every 0.1 s: the end-to-end predicates ask a page or the server, so polling is not free.
    """
    waiting.wait_until(predicate, timeout_s, what, poll_s=0.1)


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


@contextmanager
def module_page(
    server: RunningServer, browser: Browser, module: str, name: str | None = None
) -> Iterator[Page]:
    """A page of the server with ``/static/js/<module>.js`` imported as ``window.<name>``
    (default: the module's file name, e.g. ``manual`` for ``core/manual``), to run a page
    module's pure functions against their Python twins."""
    opened = browser.new_page()
    opened.goto(server.url + "/")
    url = f"/static/js/{module}.js"
    global_name = name or module.rsplit("/", 1)[-1]
    opened.evaluate(f"async () => {{ window[{global_name!r}] = await import({url!r}); }}")
    try:
        yield opened
    finally:
        opened.close()


# A minimal relay: logs in, answers the vehicle's offer with a plain RTCPeerConnection, sends
# what it is told on the `autopilot` channel and keeps the vehicle's error replies.
FAKE_RELAY = """
async ({wsUrl, room}) => {
  const ws = new WebSocket(wsUrl);
  await new Promise((resolve) => { ws.onopen = resolve; });
  const pc = new RTCPeerConnection();
  const relay = { errors: [], channel: null, ws, timer: null };
  window.fakeRelay = relay;
  let vehicle = null;
  pc.ondatachannel = ({ channel }) => {
    channel.onmessage = (event) => {
      const msg = JSON.parse(event.data);
      if (msg.type === 'error') relay.errors.push(msg);
    };
    // Bad messages and goals go on the reliable channel (the vehicle serves goals on both).
    if (channel.label === 'autopilot') channel.onopen = () => { relay.channel = channel; };
  };
  pc.onicecandidate = ({ candidate }) => {
    if (!candidate) return;
    ws.send(JSON.stringify({ type: 'candidate', to: vehicle, candidate: candidate.toJSON() }));
  };
  ws.onmessage = async (event) => {
    const msg = JSON.parse(event.data);
    if (msg.type === 'offer') {
      vehicle = msg.from;
      await pc.setRemoteDescription({ type: 'offer', sdp: msg.sdp });
      await pc.setLocalDescription();
      ws.send(JSON.stringify({ type: 'answer', to: vehicle, sdp: pc.localDescription.sdp }));
    } else if (msg.type === 'candidate' && msg.candidate) {
      await pc.addIceCandidate(msg.candidate);
    }
  };
  ws.send(JSON.stringify({ type: 'login', name: 'fake-relay', role: 'relay', room }));
}
"""


class Touches:
    """Fingers on a touch screen page (a context with ``has_touch``), through Chromium's input
    pipeline as a phone's are: ``Input.dispatchTouchEvent`` takes every finger down with a
    touchStart or touchMove, the fingers lifting with a touchEnd, and none with a touchCancel
    (which cancels them all)."""

    def __init__(self, page: Page) -> None:
        self.cdp: CDPSession = page.context.new_cdp_session(page)
        self.down: dict[int, tuple[float, float]] = {}

    def _send(self, kind: str, points: dict[int, tuple[float, float]]) -> None:
        touch_points = [{"x": x, "y": y, "id": finger} for finger, (x, y) in points.items()]
        self.cdp.send("Input.dispatchTouchEvent", {"type": kind, "touchPoints": touch_points})

    def press(self, finger: int, x: float, y: float) -> None:
        self.down[finger] = (x, y)
        self._send("touchStart", self.down)

    def move(self, finger: int, x: float, y: float, steps: int = 5) -> None:
        x0, y0 = self.down[finger]
        for step in range(1, steps + 1):
            self.down[finger] = (x0 + (x - x0) * step / steps, y0 + (y - y0) * step / steps)
            self._send("touchMove", self.down)

    def lift(self, finger: int) -> None:
        self._send("touchEnd", {finger: self.down.pop(finger)})

    def cancel(self) -> None:
        """The browser cancels every touch (as when a call comes in)."""
        self.down.clear()
        self._send("touchCancel", {})
