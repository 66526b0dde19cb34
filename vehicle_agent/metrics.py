"""The vehicle agent's Prometheus metrics, read off its event log (``autopilot vehicle
--metrics-port``).

:class:`VehicleMetrics` listens to :class:`~vehicle_agent.events.EventLog`: the agent's loop
knows nothing of it. The goal age is the time since the previous goal applied on the same link,
i.e. how old the goal the turtle was steering by had become when a newer one replaced it (the
``goalAgeMs`` the agent reports in its pose telemetry, observed at each goal). It is not the
relay-to-vehicle delay: the goal message's own ``t`` is the relay's clock, which this machine's
need not match (see :mod:`vehicle_agent.core.freshness`).
"""

from __future__ import annotations

import argparse
from typing import Final, get_args

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram

from app.metrics import MetricsServer, serve_metrics
from app.protocol import events as ev
from vehicle_agent.events import EventLog

# The ``why`` label's values: the latest-wins verdicts and goals ignored in manual mode.
DROP_REASONS: Final = get_args(ev.DropReason)
# Seconds: the relay's profiles send a goal every 30 to 300 ms; a second or more is an outage.
GOAL_AGE_BUCKETS: Final = (0.025, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0, 2.0, 5.0)


class VehicleMetrics:
    """The agent's series, in a registry of their own; :meth:`on_event` is an event listener."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.goals_applied = Counter(
            "autopilot_vehicle_goals_applied_total",
            "Goals received and applied (fresh, newest, in auto mode)",
            registry=self.registry,
        )
        self.goals_dropped = Counter(
            "autopilot_vehicle_goals_dropped_total",
            "Goals received and not applied, by why: old (seq not newer), stale (late), manual",
            ["why"],
            registry=self.registry,
        )
        self.goal_age = Histogram(
            "autopilot_vehicle_goal_age_seconds",
            "Time since the previous goal applied on the same link, at each goal applied",
            buckets=GOAL_AGE_BUCKETS,
            registry=self.registry,
        )
        self.twists = Counter(
            "autopilot_vehicle_twists_total",
            "Twists published to the turtle (stops included)",
            registry=self.registry,
        )
        self.link_up = Gauge(
            "autopilot_vehicle_link_up",
            "1 while the WebRTC link to the relay is up, else 0",
            registry=self.registry,
        )
        self.mode = Gauge(
            "autopilot_vehicle_mode",
            "0 in auto mode (goals steer), 1 in manual mode (an operator holds the wheel)",
            registry=self.registry,
        )
        for why in DROP_REASONS:
            self.goals_dropped.labels(why)
        self._last_goal_t: float | None = None

    def on_event(self, event: ev.AnyEvent) -> None:
        """Count one event of the agent's :class:`~vehicle_agent.events.EventLog`."""
        match event:
            case ev.GoalApplied(t=t):
                self.goals_applied.inc()
                if self._last_goal_t is not None:
                    self.goal_age.observe(t - self._last_goal_t)
                self._last_goal_t = t
            case ev.GoalDropped(why=why):
                self.goals_dropped.labels(why).inc()
            case ev.TwistSent():
                self.twists.inc()
            case ev.LinkChanged(state=state):
                self.link_up.set(1 if state == "up" else 0)
                if state != "up":
                    # A new offer starts a new link (goal seq and age start again) and the
                    # agent returns to auto whenever a link is offered or drops.
                    self._last_goal_t = None
                    self.mode.set(0)
            case ev.ModeChanged(mode=mode):
                self.mode.set(1 if mode == "manual" else 0)
            case _:
                pass  # the other kinds are not counted


def serve_agent_metrics(args: argparse.Namespace, events: EventLog) -> MetricsServer | None:
    """The agent's metrics on the listener the command line asks for, counting ``events``;
    None when ``--metrics-port`` is not given (nothing listens to the events then)."""
    if args.metrics_port is None:
        return None
    metrics = VehicleMetrics()
    events.listeners.append(metrics.on_event)
    return serve_metrics(args, metrics.registry)
