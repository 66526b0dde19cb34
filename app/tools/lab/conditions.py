"""Named network conditions of the field lab.

Link conditions act on the robot's link (robot <-> its NAT router): loss on both ends' ingress,
the bandwidth cap on the robot's uplink, the outage on both ends. The kernel here has no netem,
so delay and jitter come from a userspace UDP stage in front of the TURN server; only relayed
traffic crosses it, which is why ``rtt_150`` also asks for the relay policy.
"""

from __future__ import annotations

from dataclasses import dataclass

from app.server.turn import IceTransportPolicy


@dataclass(frozen=True)
class Condition:
    """One named condition; zero means "not applied"."""

    name: str
    description: str
    ice_transport_policy: IceTransportPolicy = "all"
    loss_percent: int = 0
    rtt_ms: int = 0
    jitter_ms: int = 0
    uplink_kbit: int = 0
    outage_s: float = 0.0


CONDITIONS: dict[str, Condition] = {
    c.name: c
    for c in (
        Condition("clean", "through both NATs, nothing else"),
        Condition("turn_only", "relayed candidates only", ice_transport_policy="relay"),
        Condition("loss_2", "2% loss each way on the robot link", loss_percent=2),
        Condition("loss_10", "10% loss each way on the robot link", loss_percent=10),
        Condition(
            "rtt_150",
            "150 ms round trip +-20 ms on the robot's path to TURN (relayed)",
            ice_transport_policy="relay",
            rtt_ms=150,
            jitter_ms=20,
        ),
        Condition("cap_1mbit", "robot uplink capped at 1 Mbit/s", uplink_kbit=1000),
        Condition("cap_300kbit", "robot uplink capped at 300 kbit/s", uplink_kbit=300),
        Condition("link_drop", "the robot link goes dark for 3 s when asked", outage_s=3.0),
    )
}


def condition(name: str) -> Condition:
    """The condition called ``name``; an unknown name is a ValueError listing the known ones."""
    try:
        return CONDITIONS[name]
    except KeyError:
        raise ValueError(f"unknown condition {name!r}; known: {', '.join(CONDITIONS)}") from None
