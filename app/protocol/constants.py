"""Constants shared by the server, the agent, the tools and (through page config) the browser.

Everything here that a page needs is also in :func:`app.protocol.browser.browser_protocol`, which
the server embeds in every page; the JS modules read it from there (``protocol.js``) instead of
typing the numbers again.
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final, Literal

# The room a peer joins when it names none.
DEFAULT_ROOM: Final = "default"

Role = Literal["vehicle", "relay", "client"]
ROLES: Final[tuple[Role, ...]] = ("vehicle", "relay", "client")

Profile = Literal["default", "thesis"]
# Relay timing profiles: ``thesis`` reproduces the 2017 system's pacing. The vehicle profiles
# (these two and ``follow``, which the relay paces as ``default``) are
# ``app.protocol.control.PROFILES``.
PROFILES: Final[tuple[Profile, ...]] = ("default", "thesis")
RELAY_PROFILES: Final[tuple[Profile, ...]] = PROFILES
# How often the relay takes a snapshot, per profile: None is every decoded video frame.
THESIS_SNAPSHOT_PERIOD_MS: Final = 1500
RELAY_SNAPSHOT_PERIOD_MS: Final[dict[Profile, int | None]] = {
    "default": None,
    "thesis": THESIS_SNAPSHOT_PERIOD_MS,
}
DEFAULT_PROFILE: Final[Profile] = "default"

# Data-channel labels (DESIGN §3): the vehicle opens ``autopilot`` to the relay, the client
# opens ``control`` to the relay.
AUTOPILOT_CHANNEL: Final = "autopilot"
# ... and beside it the lossy ``autopilot-state`` for goals and pose (app/protocol/channels.py).
AUTOPILOT_STATE_CHANNEL: Final = "autopilot-state"
CONTROL_CHANNEL: Final = "control"


class CloseCode(IntEnum):
    """WebSocket close codes (RFC 6455 §7.4.1) the server's sockets close with."""

    NORMAL = 1000
    POLICY_VIOLATION = 1008
    TRY_AGAIN_LATER = 1013


# The turtlesim world: a square of this many metres, origin bottom-left, y up. The terrain
# centre (where turtle1 spawns, and where a goal in the middle of the frame lands) is half of it,
# written as turtlesim and the thesis write it.
WORLD_SIZE: Final = 11.088889
TERRAIN_CENTRE: Final = 5.544445

# The vehicle's video: the size a browser vehicle asks its camera for and the Python agent's
# synthetic scene, and the agent's frame rate. The relay analyses one snapshot per decoded frame,
# so the frame rate bounds goals per second and the wait for the next frame is part of every
# goal's latency.
VIDEO_SIZE: Final = (640, 480)
VIDEO_FPS: Final = 30.0
# The relay re-encodes the vehicle's video for each client at this fraction of its size per side
# (RTCRtpEncodingParameters.scaleResolutionDownBy): the operator watches it, the relay analyses
# the full-size decoded frames, and the encode is the relay's largest cost after the cascade
# (docs/bench/relay-cost.md).
CLIENT_FORWARD_SCALE_DOWN: Final = 2.0

# Frame tag (docs/contracts.md, "Frame tag"): a row of square blocks along the top edge, each
# floor(width / TAG_BLOCKS_PER_WIDTH) px; TAG_MARKER_BLOCKS marker blocks (white, black), then
# TAG_BITS bits of the frame number, most significant first.
TAG_BLOCKS_PER_WIDTH: Final = 40
TAG_MARKER_BLOCKS: Final = 2
TAG_BITS: Final = 24

# Target lock (DESIGN §10 "Which target", app/vision/lock.py and app/static/js/core/lock.js): a
# locked target not seen for LOCK_SEARCH_AFTER_S is searched for in the whole frame; not seen for
# LOCK_RELEASE_AFTER_S, the lock is released (back to the largest). A box continues the track
# only if neither side is more than LOCK_MAX_SCALE times the locked box's, and, unless searching
# the whole frame, its centre is within LOCK_REACH of the locked box's sides from its centre.
LOCK_SEARCH_AFTER_S: Final = 1.0
LOCK_RELEASE_AFTER_S: Final = 3.0
LOCK_MAX_SCALE: Final = 1.4
LOCK_REACH: Final = 1.0

# Link health (the client's panel, DESIGN §10): each link's figures are read once a HEALTH_PERIOD_S
# from the receiving side's getStats(), and a link is flagged when it loses more than
# HEALTH_MAX_LOSS_PCT of its video packets or its round trip exceeds HEALTH_MAX_RTT_MS.
HEALTH_PERIOD_S: Final = 1.0
HEALTH_MAX_LOSS_PCT: Final = 5.0
HEALTH_MAX_RTT_MS: Final = 300.0
