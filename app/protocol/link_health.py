"""Link health, the client's panel: when a WebRTC link is flagged as poor.

Each link's figures are read once a ``period_s`` from the receiving side's ``getStats()``, and a
link is flagged when it loses more than ``max_loss_pct`` of its video packets or its round trip
exceeds ``max_rtt_ms``. The page's ``link-health.js`` gets these numbers from its config.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final


@dataclass(frozen=True)
class HealthLimits:
    """The panel's period and warning thresholds (the defaults are the protocol's)."""

    period_s: float = 1.0
    max_loss_pct: float = 5.0
    max_rtt_ms: float = 300.0


HEALTH: Final = HealthLimits()
