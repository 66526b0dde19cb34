"""What the pages know of the protocol, as one JSON-ready dict rendered from the Python source.

The server embeds it in every page's config (``config.protocol``); ``app/static/js/protocol.js``
reads it there, so no JS module types a profile name, a channel label, a world size or the frame
tag layout again, and ``schema.js`` validates data-channel messages against the schemas of
:mod:`app.protocol.channels`.
"""

from __future__ import annotations

from functools import cache
from typing import Any

from app.protocol import relay_profiles as relay
from app.protocol.channels import (
    AUTOPILOT_CHANNEL,
    AUTOPILOT_STATE_CHANNEL,
    CONTROL_CHANNEL,
    GOAL_AGE_WINDOW_S,
    GOAL_MAX_AGE_S,
    STATE_CHANNEL_MAX_RETRANSMITS,
    STATE_CHANNEL_ORDERED,
    channel_schemas,
)
from app.protocol.control import PROFILES as VEHICLE_PROFILES
from app.protocol.frametag import LAYOUT
from app.protocol.link_health import HEALTH
from app.protocol.lock import LockRule
from app.protocol.rooms import DEFAULT_ROOM, ROLES
from app.protocol.video import CLIENT_FORWARD_SCALE_DOWN, VIDEO_SIZE
from app.protocol.world import TERRAIN_CENTRE, WORLD_SIZE


@cache
def browser_protocol() -> dict[str, Any]:
    """The constants and data-channel schemas every page gets (computed once, never mutated)."""
    return {
        "roles": list(ROLES),
        "defaultRoom": DEFAULT_ROOM,
        "profiles": {"relay": list(relay.PROFILES), "vehicle": list(VEHICLE_PROFILES)},
        "defaultProfile": relay.DEFAULT_PROFILE,
        "relayProfiles": {
            name: {"snapshotPeriodMs": relay.RELAY_SNAPSHOT_PERIOD_MS[name]}
            for name in relay.PROFILES
        },
        "channels": {
            "autopilot": AUTOPILOT_CHANNEL,
            "autopilotState": AUTOPILOT_STATE_CHANNEL,
            "control": CONTROL_CHANNEL,
        },
        # RTCDataChannelInit of the lossy state channel, and the latest-wins numbers.
        "stateChannelOptions": {
            "ordered": STATE_CHANNEL_ORDERED,
            "maxRetransmits": STATE_CHANNEL_MAX_RETRANSMITS,
        },
        "goalFreshness": {"maxAgeS": GOAL_MAX_AGE_S, "windowS": GOAL_AGE_WINDOW_S},
        "world": {"size": WORLD_SIZE, "terrainCentre": TERRAIN_CENTRE},
        # The frame size the vehicle page asks its camera for.
        "video": {"width": VIDEO_SIZE[0], "height": VIDEO_SIZE[1]},
        # How much smaller the relay's forward to a client is, per side.
        "clientForwardScaleDown": CLIENT_FORWARD_SCALE_DOWN,
        "frameTag": {
            "blocksPerWidth": LAYOUT.blocks_per_width,
            "markerBlocks": LAYOUT.marker_blocks,
            "bits": LAYOUT.bits,
        },
        # The target lock's rule (app/vision/lock.py, app/static/js/lock.js).
        "lock": {
            "searchAfterS": LockRule().search_after_s,
            "releaseAfterS": LockRule().release_after_s,
            "maxScale": LockRule().max_scale,
            "reach": LockRule().reach,
        },
        # The link health panel's period and warning thresholds (link-health.js).
        "health": {
            "periodS": HEALTH.period_s,
            "maxLossPct": HEALTH.max_loss_pct,
            "maxRttMs": HEALTH.max_rtt_ms,
        },
        # schemas[channel label][receiving role]: JSON Schema (draft 2020-12 subset, schema.js).
        "schemas": channel_schemas(),
    }
