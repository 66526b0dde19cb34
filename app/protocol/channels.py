"""The vehicle's data channels to the relay, and the latest-wins numbers (DESIGN §9).

The vehicle opens two channels. ``autopilot`` is reliable and ordered: mode commands (``stop``)
and error reports, which must arrive. ``autopilot-state`` is unordered and never retransmits:
goals (relay -> vehicle) and pose (vehicle -> relay) are state, only the newest matters, and a
lost one is better skipped than waited for (no head-of-line blocking on a lossy link). The
vehicle applies a goal only if its ``seq`` is newer than every goal applied on this link and it
is not stale (see ``vehicle_agent/freshness.py`` and ``app/static/js/freshness.js``).
"""

from __future__ import annotations

from typing import Any, Final

CONTROL_CHANNEL: Final = "autopilot"
STATE_CHANNEL: Final = "autopilot-state"
# RTCDataChannelInit of the state channel (aiortc takes the same two keyword arguments).
STATE_CHANNEL_ORDERED: Final = False
STATE_CHANNEL_MAX_RETRANSMITS: Final = 0
# A goal that took this much longer than the quickest goal of the last GOAL_AGE_WINDOW_S on its
# way is stale and dropped.
GOAL_MAX_AGE_S: Final = 0.5
GOAL_AGE_WINDOW_S: Final = 5.0


def page_channels() -> dict[str, Any]:
    """The same facts for a page's embedded config."""
    return {
        "control": CONTROL_CHANNEL,
        "state": {
            "label": STATE_CHANNEL,
            "options": {
                "ordered": STATE_CHANNEL_ORDERED,
                "maxRetransmits": STATE_CHANNEL_MAX_RETRANSMITS,
            },
        },
        "goalFreshness": {"maxAgeS": GOAL_MAX_AGE_S, "windowS": GOAL_AGE_WINDOW_S},
    }
