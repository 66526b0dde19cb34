"""What the pages know of the protocol, as one JSON-ready dict rendered from the Python source.

The server embeds it in every page's config (``config.protocol``); ``app/static/js/config.js``
reads it there, so no JS module types a profile name, a channel label, a world size or the frame
tag layout again, and ``schema.js`` validates data-channel messages against the schemas of
:mod:`app.protocol.channels`.
"""

from __future__ import annotations

from functools import cache
from typing import Any

from app.protocol import constants as c
from app.protocol.channels import (
    GOAL_AGE_WINDOW_S,
    GOAL_MAX_AGE_S,
    STATE_CHANNEL_MAX_RETRANSMITS,
    STATE_CHANNEL_ORDERED,
    channel_schemas,
)
from app.protocol.control import PROFILES as VEHICLE_PROFILES


@cache
def browser_protocol() -> dict[str, Any]:
    """The constants and data-channel schemas every page gets (computed once, never mutated)."""
    return {
        "roles": list(c.ROLES),
        "defaultRoom": c.DEFAULT_ROOM,
        "profiles": {"relay": list(c.RELAY_PROFILES), "vehicle": list(VEHICLE_PROFILES)},
        "defaultProfile": c.DEFAULT_PROFILE,
        "relayProfiles": {
            name: {"snapshotPeriodMs": c.RELAY_SNAPSHOT_PERIOD_MS[name]}
            for name in c.RELAY_PROFILES
        },
        "channels": {
            "autopilot": c.AUTOPILOT_CHANNEL,
            "autopilotState": c.AUTOPILOT_STATE_CHANNEL,
            "control": c.CONTROL_CHANNEL,
        },
        # RTCDataChannelInit of the lossy state channel, and the latest-wins numbers.
        "stateChannelOptions": {
            "ordered": STATE_CHANNEL_ORDERED,
            "maxRetransmits": STATE_CHANNEL_MAX_RETRANSMITS,
        },
        "goalFreshness": {"maxAgeS": GOAL_MAX_AGE_S, "windowS": GOAL_AGE_WINDOW_S},
        "world": {"size": c.WORLD_SIZE, "terrainCentre": c.TERRAIN_CENTRE},
        # The frame size the vehicle page asks its camera for.
        "video": {"width": c.VIDEO_SIZE[0], "height": c.VIDEO_SIZE[1]},
        # How much smaller the relay's forward to a client is, per side.
        "clientForwardScaleDown": c.CLIENT_FORWARD_SCALE_DOWN,
        "frameTag": {
            "blocksPerWidth": c.TAG_BLOCKS_PER_WIDTH,
            "markerBlocks": c.TAG_MARKER_BLOCKS,
            "bits": c.TAG_BITS,
        },
        # The target lock's rule (app/vision/lock.py, app/static/js/core/lock.js).
        "lock": {
            "searchAfterS": c.LOCK_SEARCH_AFTER_S,
            "releaseAfterS": c.LOCK_RELEASE_AFTER_S,
            "maxScale": c.LOCK_MAX_SCALE,
            "reach": c.LOCK_REACH,
        },
        # The link health panel's period and warning thresholds (link-health.js).
        "health": {
            "periodS": c.HEALTH_PERIOD_S,
            "maxLossPct": c.HEALTH_MAX_LOSS_PCT,
            "maxRttMs": c.HEALTH_MAX_RTT_MS,
        },
        # schemas[channel label][receiving role]: JSON Schema (draft 2020-12 subset, schema.js).
        "schemas": channel_schemas(),
    }
