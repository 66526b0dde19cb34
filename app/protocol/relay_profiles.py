"""The relay's timing profiles: how often it takes a snapshot of the vehicle's video.

``thesis`` reproduces the 2017 system's pacing. The vehicle profiles (these two and ``follow``,
which the relay paces as ``default``) are ``app.protocol.control.PROFILES``.
"""

from __future__ import annotations

from typing import Final, Literal

Profile = Literal["default", "thesis"]
PROFILES: Final[tuple[Profile, ...]] = ("default", "thesis")
DEFAULT_PROFILE: Final[Profile] = "default"
# How often the relay takes a snapshot, per profile: None is every decoded video frame.
THESIS_SNAPSHOT_PERIOD_MS: Final = 1500
RELAY_SNAPSHOT_PERIOD_MS: Final[dict[Profile, int | None]] = {
    "default": None,
    "thesis": THESIS_SNAPSHOT_PERIOD_MS,
}
