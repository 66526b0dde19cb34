"""Headless Chromium for the relay service, parity runs, tests and benchmarks.

Playwright cannot download browsers here, so we drive Debian's ``chromium`` through
``executable_path`` (overridable with ``AUTOPILOT_CHROMIUM``).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

# Flags that work headless as root on these machines (DESIGN §8). mDNS host candidates are
# turned off so that aiortc and other Chromium instances can reach a page's host candidate.
BASE_FLAGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--use-fake-ui-for-media-stream",
    "--use-fake-device-for-media-stream",
    "--autoplay-policy=no-user-gesture-required",
    "--disable-features=WebRtcHideLocalIpsWithMdns",
    # A hidden or unfocused headless page must keep its timers and video frames running.
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
]


class BrowserNotFound(RuntimeError):
    """No Chromium executable could be found."""


def chromium_path() -> str:
    """Path of the Chromium executable: ``AUTOPILOT_CHROMIUM``, else the first on PATH."""
    override = os.environ.get("AUTOPILOT_CHROMIUM")
    if override:
        if not Path(override).exists():
            raise BrowserNotFound(f"AUTOPILOT_CHROMIUM={override} does not exist")
        return override
    for name in CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    raise BrowserNotFound(
        "no Chromium found: install Debian's package (apt-get install -y chromium) "
        "or set AUTOPILOT_CHROMIUM to its path"
    )


def chromium_args(fake_video: Path | None = None) -> list[str]:
    """Command-line flags; ``fake_video`` (.y4m or .mjpeg) becomes the fake camera."""
    args = list(BASE_FLAGS)
    if fake_video is not None:
        args.append(f"--use-file-for-fake-video-capture={fake_video.resolve()}")
    return args
