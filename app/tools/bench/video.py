"""What Chromium's video sender gives up on a capped link, per content hint and degradation
preference: the measurement behind the pages leaving Chromium's default on the video they send.

A headless Chromium at the robot site sends a busy 640x480 canvas at 30 fps (coloured blocks
sliding over the whole frame, so the encoder wants far more than the cap) straight to a
headless Chromium in the cloud: the SDP is handed over by Playwright, ICE uses host
candidates through the robot's NAT. The robot's uplink is capped (the lab's ``cap_*``
conditions). After the bandwidth estimate has settled, the receiver's ``inbound-rtp`` stats
give the frames decoded per second and the frame width, for each variant:

- no hint: the browser's default for a canvas track (``balanced``);
- ``contentHint = "motion"``: keep the frame rate, lower the resolution first;
- ``contentHint = "detail"``: keep the resolution, drop frames;
- ``degradationPreference = "maintain-framerate"`` set with ``RTCRtpSender.setParameters``.

The control loop needs frames (a goal per frame), not pixels: the relay analyses a 256 px-wide
copy of each frame anyway. On this machine the default kept the most (README, "Performance").
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Any

from app.chromium import chromium_path, launch_options

if TYPE_CHECKING:
    from playwright.sync_api import Page, Playwright

    from app.tools.lab import Lab

log = logging.getLogger(__name__)

# (contentHint, degradationPreference set on the sender, or None to leave it to the hint).
VARIANTS = (("", None), ("motion", None), ("detail", None), ("", "maintain-framerate"))
CAPS = {"quick": ("cap_300kbit",), "full": ("cap_300kbit", "cap_1mbit")}
# Seconds for the bandwidth estimate and the encoder's adaptation to settle, then measured.
SETTLE_S = {"quick": 6.0, "full": 10.0}
WINDOW_S = {"quick": 6.0, "full": 15.0}

# The end of both peers' set-up: no trickle, the description is returned with every candidate.
_GATHERED_JS = """  await new Promise((resolve) => {
    if (pc.iceGatheringState === 'complete') resolve();
    pc.addEventListener('icegatheringstatechange', () => {
      if (pc.iceGatheringState === 'complete') resolve();
    });
  });
  return pc.localDescription.toJSON();
}"""

_SENDER_JS = (
    """async (hint) => {
  const canvas = document.createElement('canvas');
  canvas.width = 640;
  canvas.height = 480;
  const ctx = canvas.getContext('2d');
  let n = 0;
  setInterval(() => {
    n += 1;
    ctx.fillStyle = '#404040';
    ctx.fillRect(0, 0, 640, 480);
    for (let i = 0; i < 300; i += 1) {
      ctx.fillStyle = `hsl(${(i * 37 + n * 5) % 360}, 70%, ${30 + (i % 5) * 10}%)`;
      ctx.fillRect((i * 53 + n * (1 + (i % 7))) % 640, (i * 97 + n * (i % 3)) % 480, 20, 20);
    }
  }, 33);
  const stream = canvas.captureStream(30);
  const track = stream.getVideoTracks()[0];
  track.contentHint = hint;
  const pc = new RTCPeerConnection();
  window.pc = pc;
  window.sender = pc.addTrack(track, stream);
  await pc.setLocalDescription(await pc.createOffer());
"""
    + _GATHERED_JS
)

_RECEIVER_JS = (
    """async (offer) => {
  const pc = new RTCPeerConnection();
  window.pc = pc;
  await pc.setRemoteDescription(offer);
  await pc.setLocalDescription(await pc.createAnswer());
"""
    + _GATHERED_JS
)

_INBOUND_JS = """async () => {
  const stats = await window.pc.getStats();
  for (const report of stats.values()) {
    if (report.type === 'inbound-rtp' && report.kind === 'video') {
      return {frames: report.framesDecoded ?? 0, width: report.frameWidth ?? 0,
              bytes: report.bytesReceived ?? 0};
    }
  }
  return {frames: 0, width: 0, bytes: 0};
}"""

_PREFERENCE_JS = """async (preference) => {
  const params = window.sender.getParameters();
  if (preference !== null) {
    params.degradationPreference = preference;
    try {
      await window.sender.setParameters(params);
    } catch (err) {
      return `refused: ${err.message}`;
    }
  }
  return window.sender.getParameters().degradationPreference ?? '(unset)';
}"""

_OUTBOUND_JS = """async () => {
  const stats = await window.pc.getStats();
  for (const report of stats.values()) {
    if (report.type === 'outbound-rtp' && report.kind === 'video') {
      return report.qualityLimitationReason ?? null;
    }
  }
  return null;
}"""


def measure(
    lab: Lab, playwright: Playwright, quick: bool, seconds: float | None = None
) -> list[dict[str, Any]]:
    """One row per (cap, variant): received frames/s, frame width, kbit/s and what limited it;
    ``seconds`` (``--seconds``) replaces the plan's window, and caps its settling time."""
    plan = "quick" if quick else "full"
    settle_s, window_s = SETTLE_S[plan], WINDOW_S[plan]
    if seconds is not None:
        settle_s, window_s = min(settle_s, seconds), seconds
    rows = []
    for cap in CAPS[plan]:
        lab.apply(cap)
        browsers = [
            playwright.chromium.launch(
                **launch_options(executable=str(lab.chromium(site, chromium_path())))
            )
            for site in ("robot", "cloud")
        ]
        try:
            for hint, preference in VARIANTS:
                # Fresh pages, hence a fresh peer connection with its own bandwidth estimate
                # and encoder, in the same two browsers.
                sender, receiver = (browser.new_page() for browser in browsers)
                try:
                    row = _run(sender, receiver, hint, preference, settle_s, window_s)
                finally:
                    sender.close()
                    receiver.close()
                rows.append({"condition": cap, "hint": hint or "(none)", **row})
                log.info("video under %s: %s", cap, rows[-1])
        finally:
            for browser in browsers:
                browser.close()
    return rows


def _run(
    sender: Page,
    receiver: Page,
    hint: str,
    preference: str | None,
    settle_s: float,
    window_s: float,
) -> dict[str, Any]:
    offer = sender.evaluate(_SENDER_JS, hint)
    answer = receiver.evaluate(_RECEIVER_JS, offer)
    sender.evaluate("(answer) => window.pc.setRemoteDescription(answer)", answer)
    # What the sender runs with: the preference asked for, if the browser took it.
    applied = sender.evaluate(_PREFERENCE_JS, preference)
    time.sleep(settle_s)
    before = receiver.evaluate(_INBOUND_JS)
    started = time.monotonic()
    time.sleep(window_s)
    after = receiver.evaluate(_INBOUND_JS)
    elapsed = time.monotonic() - started
    return {
        "fps": round((after["frames"] - before["frames"]) / elapsed, 1),
        "width": after["width"],
        "kbit_per_s": round((after["bytes"] - before["bytes"]) * 8 / elapsed / 1000),
        "degradation_preference": applied,
        "limited_by": sender.evaluate(_OUTBOUND_JS),
    }
