"""The server's Prometheus metrics (``autopilot serve``, and the demo's server).

Counters move as things happen: the hub reports every frame it reads and every refusal
(:class:`~app.signaling.hub.HubMetrics`), the socket layer its caps and slow readers, the origin
guard and the rosbridge gate theirs. Gauges (rooms, peers, rosbridge sessions, the simulator's
tick rate) are sampled once a second on the event loop, which owns the hub and the simulator:
the metrics listener's thread never reads their state while the loop changes it.

Every label takes values from a fixed set: roles, the protocol's message types (anything else is
``other``), and :data:`app.signaling.hub.REFUSALS`. No room name is ever a label.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Sized
from typing import Final, Protocol

from prometheus_client import CollectorRegistry, Counter, Gauge

from app.protocol.rooms import ROLES
from app.protocol.signaling import INCOMING_TYPES
from app.signaling.hub import REFUSALS, Census, Refusal

# The ``type`` label's values: what a peer may send, and one bucket for everything else.
MESSAGE_TYPES: Final = (*sorted(INCOMING_TYPES), "other")
SAMPLE_PERIOD_S: Final = 1.0


class CensusSource(Protocol):
    """A hub that can say who is in it (:class:`~app.signaling.hub.Hub` or the fleet's)."""

    def census(self) -> Census: ...


class TickSource(Protocol):
    """The server's simulator, as its gauges read it (:class:`app.server.rosbridge.Simulator`):
    the steps taken so far and the open rosbridge sessions."""

    @property
    def ticks(self) -> int: ...

    @property
    def outboxes(self) -> Sized: ...


class ServerMetrics:
    """The server's series, in a registry of their own (one per app)."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.rooms = Gauge(
            "autopilot_rooms", "Rooms with at least one peer logged in", registry=self.registry
        )
        self.peers = Gauge(
            "autopilot_peers", "Peers logged in, by role", ["role"], registry=self.registry
        )
        self.messages = Counter(
            "autopilot_signaling_messages_total",
            "Signaling frames read, by message type (unknown types and unparsable frames: other)",
            ["type"],
            registry=self.registry,
        )
        self.refusals = Counter(
            "autopilot_refusals_total",
            "Connections, logins and messages refused, by reason",
            ["reason"],
            registry=self.registry,
        )
        self.rosbridge_sessions = Gauge(
            "autopilot_rosbridge_sessions", "Open /rosbridge connections", registry=self.registry
        )
        self.tick_rate = Gauge(
            "autopilot_simulator_tick_rate_hz",
            "Simulator steps per second over the last sampling period",
            registry=self.registry,
        )
        # Every series exists from the start at 0: a dashboard shows 0, not "no data", and
        # rate() sees the first increment.
        for role in ROLES:
            self.peers.labels(role)
        for kind in MESSAGE_TYPES:
            self.messages.labels(kind)
        for reason in REFUSALS:
            self.refusals.labels(reason)

    def message(self, kind: str) -> None:
        """Count a frame read, as ``kind`` when the protocol knows it, else ``other``."""
        self.messages.labels(kind if kind in INCOMING_TYPES else "other").inc()

    def refused(self, reason: Refusal) -> None:
        """Count a refusal."""
        self.refusals.labels(reason).inc()

    def sample(self, census: Census, rosbridge_sessions: int) -> None:
        """Set the gauges of who is connected."""
        self.rooms.set(census.rooms)
        for role in ROLES:
            self.peers.labels(role).set(census.peers.get(role, 0))
        self.rosbridge_sessions.set(rosbridge_sessions)

    async def run(
        self, hub: CensusSource, simulator: TickSource, period_s: float = SAMPLE_PERIOD_S
    ) -> None:
        """Sample the gauges every ``period_s`` until cancelled."""
        ticks, at = simulator.ticks, time.monotonic()
        while True:
            self.sample(hub.census(), len(simulator.outboxes))
            await asyncio.sleep(period_s)
            now = time.monotonic()
            self.tick_rate.set((simulator.ticks - ticks) / (now - at))
            ticks, at = simulator.ticks, now
