"""Headless Chromium for the relay service, parity runs, tests and benchmarks.

Playwright cannot download browsers here, so we drive Debian's ``chromium`` through
``executable_path`` (overridable with ``AUTOPILOT_CHROMIUM``).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import TypedDict

from app.server.tls import spki_sha256

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

# Features turned off. Chromium reads only the last --disable-features, and ours comes after
# Playwright's, so it repeats Playwright's list (its chromiumSwitches.ts, less the Windows and
# Edge ones): without it Chromium would look for Cast devices on the network (MediaRouter), fetch
# optimization hints, ask for the network time, preconnect to a search engine and try HTTPS first
# for our plain-HTTP pages. Then ours:
# - mDNS host candidates, so that aiortc and other Chromium instances can reach a page's host
#   candidate;
# - the omnibox popup drawn as a web page, which Chromium 156 preloads in a renderer of its own
#   at every start even headless, where nothing can open it: the larger part of what a launch
#   costs, and the suite launches Chromium many times (docs/testing.md).
DISABLED_FEATURES = (
    "AvoidUnnecessaryBeforeUnloadCheckSync",
    "DestroyProfileOnBrowserClose",
    "HttpsUpgrades",
    "HttpsFirstBalancedModeAutoEnable",
    "LensOverlay",
    "MediaRouter",
    "PaintHolding",
    "ThirdPartyStoragePartitioning",
    "AvoidCorsURLLoaderRestartOnRedirect",
    "OptimizationHints",
    "NetworkTimeServiceQuerying",
    "AimEnabled",
    "PreconnectToSearch",
    "WebRtcHideLocalIpsWithMdns",
    "WebUIOmniboxPopup",
    "WebUIOmniboxAimPopup",
    "WebUIOmniboxFullPopup",
)

# Flags that work headless as root on these machines (docs/architecture.md, "Pinned facts").
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
    f"--disable-features={','.join(DISABLED_FEATURES)}",
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


class LaunchOptions(TypedDict):
    """Keyword arguments of Playwright's ``chromium.launch``."""

    executable_path: str
    args: list[str]
    headless: bool


def launch_options(
    fake_video: Path | None = None,
    *,
    trust_ca: Path | None = None,
    extra_args: Sequence[str] = (),
    executable: str | None = None,
) -> LaunchOptions:
    """How to launch our headless Chromium: ``playwright.chromium.launch(**launch_options())``.

    ``fake_video`` (.y4m or .mjpeg) becomes the fake camera; ``trust_ca`` admits the
    certificates that CA signed; ``executable`` replaces :func:`chromium_path` (the lab wraps
    Chromium to run it in a site).
    """
    args = list(BASE_FLAGS)
    if fake_video is not None:
        args.append(f"--use-file-for-fake-video-capture={fake_video.resolve()}")
    if trust_ca is not None:
        # Chromium cannot be handed a CA file; pinning the CA's key admits exactly the
        # certificates it signed (the server presents the CA with its certificate).
        args.append(f"--ignore-certificate-errors-spki-list={spki_sha256(trust_ca)}")
    return LaunchOptions(
        executable_path=executable or chromium_path(), args=[*args, *extra_args], headless=True
    )
