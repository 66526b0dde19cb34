"""The relay's forward of the vehicle's video: passed through as the vehicle encoded it, to a
client that joined before the vehicle and to one that joined after it, which can start only on a
key frame the relay asks the vehicle for (Chromium's encoder sends none unasked); and encoded
again at half size for each client where the relay's browser has no encoded transforms. With
the Python agent as the vehicle (its frames carry the frame tag, and it sends their capture
times) the client measures glass to glass from the frame tags it presents, at either size.
"""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import cv2
import numpy as np
import pytest
from playwright.sync_api import Browser, Page, expect

from app.protocol import frametag
from app.protocol.video import CLIENT_FORWARD_SCALE_DOWN, VIDEO_SIZE
from app.server.serve import RunningServer
from app.tools.bench.relaycost import NO_ENCODED_TRANSFORMS
from e2e.conftest import OpenRole
from e2e.helpers import VIDEO, status, wait_for_live_video

pytestmark = [pytest.mark.e2e, pytest.mark.browser, pytest.mark.slow]

ROOM = "forward"


@contextmanager
def agent(server: RunningServer) -> Iterator[subprocess.Popen[bytes]]:
    """The Python vehicle agent (synthetic face video, tagged) in the room, as a process."""
    process = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "vehicle_agent",
            "--server",
            server.url,
            "--room",
            ROOM,
            "--name",
            "vehicle",
            "--fps",
            "15",
        ],  # fmt: skip
        stdin=subprocess.DEVNULL,
    )
    try:
        yield process
    finally:
        process.terminate()
        process.wait(timeout=15)


def open_joined(open_role: OpenRole, role: str, browser: Browser, **extra: Any) -> Page:
    page = open_role(role, browser, room=ROOM, auto="1", **extra)
    expect(page.get_by_test_id("state")).to_contain_text(f"joined room {ROOM}")
    return page


def video_width(page: Page) -> int:
    width: int = page.evaluate(f"() => {VIDEO}.videoWidth")
    return width


def glass_to_glass(client: Page) -> dict[str, float] | None:
    health: dict[str, Any] = client.evaluate("() => structuredClone(window.autopilotHealth)")
    figure: dict[str, float] | None = health["glassToGlass"]
    return figure


def wait_for_glass_to_glass(client: Page) -> dict[str, float]:
    """The client's figure once it has measured a few frames: present and positive (one
    machine's clock: a frame is shown after it was captured)."""
    client.wait_for_function(
        "() => (window.autopilotHealth.glassToGlass?.frames ?? 0) >= 10", timeout=60_000
    )
    figure = glass_to_glass(client)
    assert figure is not None
    assert 0 < figure["p50Ms"] <= figure["p95Ms"], figure
    # The live figure beside the video: the median, and the 95th percentile in brackets.
    expect(client.get_by_test_id("glass-to-glass")).to_have_text(
        re.compile(r"^\d+ ms \(p95 \d+\)$")
    )
    return figure


# Where the picture stands in the <video> element (object-fit: contain) and at what scale.
PICTURE_JS = f"""() => {{
  const v = {VIDEO};
  const scale = Math.min(v.clientWidth / v.videoWidth, v.clientHeight / v.videoHeight);
  return {{
    scale,
    top: (v.clientHeight - v.videoHeight * scale) / 2,
    left: (v.clientWidth - v.videoWidth * scale) / 2,
    width: v.videoWidth,
    clientWidth: v.clientWidth,
  }};
}}"""


def tag_as_shown(client: Page) -> np.ndarray:
    """The grey levels the operator sees where the frame tag's blocks are (their middle rows)."""
    shot = client.get_by_test_id("video").screenshot()
    image = cv2.imdecode(np.frombuffer(shot, np.uint8), cv2.IMREAD_GRAYSCALE)
    picture: dict[str, float] = client.evaluate(PICTURE_JS)
    ratio = image.shape[1] / picture["clientWidth"]  # screenshot pixels per CSS pixel
    block = frametag.block_size(int(picture["width"])) * picture["scale"]
    blocks = frametag.LAYOUT.marker_blocks + frametag.LAYOUT.bits
    y0, y1 = (round((picture["top"] + f * block) * ratio) for f in (0.25, 0.75))
    x0, x1 = (round((picture["left"] + n * block) * ratio) for n in (0, blocks))
    strip: np.ndarray = image[y0:y1, x0:x1]
    return strip


def test_passed_through_to_clients_that_join_before_and_after_the_vehicle(
    open_role: OpenRole, browser: Browser, vehicle_browser: Browser
) -> None:
    relay = open_joined(open_role, "relay", browser, name="relay")
    early = open_joined(open_role, "client", browser, name="early")
    open_joined(open_role, "vehicle", vehicle_browser, name="vehicle")
    wait_for_live_video(early)
    assert status(relay)["forwards"] == {"early": "pass-through"}
    # The vehicle's own frames, at the vehicle's own size: nothing encoded them again.
    assert video_width(early) == VIDEO_SIZE[0]

    late = open_joined(open_role, "client", browser, name="late")
    # A picture soon, although the vehicle's encoder sent its one key frame long ago.
    late.wait_for_function(f"() => {VIDEO}.videoWidth > 0", timeout=20_000)
    wait_for_live_video(late)
    assert status(relay)["forwards"] == {"early": "pass-through", "late": "pass-through"}
    assert video_width(late) == VIDEO_SIZE[0]


def test_the_client_measures_glass_to_glass_on_the_vehicle_s_frames(
    open_role: OpenRole, browser: Browser, server: RunningServer
) -> None:
    relay = open_joined(open_role, "relay", browser, name="relay")
    client = open_joined(open_role, "client", browser, name="client")
    with agent(server):
        wait_for_live_video(client)
        # aiortc numbers its codecs unlike Chromium: the relay's answer renumbered them.
        assert status(relay)["forwards"] == {"client": "pass-through"}
        assert video_width(client) == VIDEO_SIZE[0]
        wait_for_glass_to_glass(client)
        # The tag stays in the stream (the figure reads it) but not in the picture: where its
        # white marker and black blocks are, the operator sees one even colour.
        strip = tag_as_shown(client)
        assert strip.size > 0 and float(strip.std()) < 4.0, float(strip.std())
    # The camera stopped with the vehicle: the figure no longer passes for a live one.
    figure = client.get_by_test_id("glass-to-glass")
    expect(figure).to_have_text("–", timeout=15_000)
    expect(figure).to_have_attribute("title", re.compile("^stale"))


def test_without_encoded_transforms_the_relay_encodes_for_each_client(
    open_role: OpenRole, browser: Browser, server: RunningServer
) -> None:
    # The relay page as in a browser without encoded transforms.
    relay = open_role("relay", browser, NO_ENCODED_TRANSFORMS, room=ROOM, name="relay", auto="1")
    client = open_joined(open_role, "client", browser, name="client")
    with agent(server):
        wait_for_live_video(client)
        assert status(relay)["forwards"] == {"client": "re-encode"}
        # Encoded again at the forward's smaller size, and its frame tags still read.
        assert video_width(client) == VIDEO_SIZE[0] / CLIENT_FORWARD_SCALE_DOWN
        wait_for_glass_to_glass(client)
