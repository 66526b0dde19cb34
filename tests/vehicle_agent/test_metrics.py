"""The vehicle agent's metrics: the real agent's handlers, fed data-channel messages the way the
data channel feeds them, move the counters that its ``/metrics`` listener then serves."""

from __future__ import annotations

import json
import time
from typing import Any

import pytest

from app.metrics import start_metrics_server
from app.protocol import events as ev
from tests.helpers.agent import H, Vehicle, W
from tests.helpers.metrics import scrape
from vehicle_agent.metrics import DROP_REASONS, VehicleMetrics


def goal(seq: int, t_ms: float) -> str:
    return json.dumps(
        {"type": "goal", "seq": seq, "op": "face", "x": 10, "y": 100, "w": W, "h": H, "t": t_ms}
    )


def test_goals_twists_and_mode_of_the_real_agent_are_served() -> None:
    vehicle = Vehicle("default")
    metrics = VehicleMetrics()
    vehicle.agent.events.listeners.append(metrics.on_event)
    listener = start_metrics_server(metrics.registry, 0)
    try:
        before = scrape(listener.url)
        for why in DROP_REASONS:
            assert before[("autopilot_vehicle_goals_dropped_total", (("why", why),))] == 0

        def send(message: str | dict[str, Any]) -> None:
            text = message if isinstance(message, str) else json.dumps(message)
            assert vehicle.agent.handle_channel_message(text, "relay") is None

        now_ms = time.time() * 1000
        send(goal(1, now_ms))
        time.sleep(0.05)
        send(goal(2, now_ms + 50))
        send(goal(2, now_ms + 60))  # not newer: old
        send(goal(3, now_ms - 5000))  # five seconds later than the quickest: stale
        send({"type": "mode", "mode": "manual", "operator": "c"})
        manual = scrape(listener.url)[("autopilot_vehicle_mode", ())]
        send(goal(4, now_ms + 100))  # the operator holds the wheel: ignored
        send({"type": "mode", "mode": "auto"})
        after = scrape(listener.url)
    finally:
        listener.close()
    twists = vehicle.twists()
    assert after[("autopilot_vehicle_goals_applied_total", ())] == 2
    for why, count in {"old": 1, "stale": 1, "manual": 1}.items():
        assert after[("autopilot_vehicle_goals_dropped_total", (("why", why),))] == count
    assert after[("autopilot_vehicle_twists_total", ())] == len(twists) > 0
    assert manual == 1 and after[("autopilot_vehicle_mode", ())] == 0
    # One age: between the two goals applied, 50 ms apart (plus the handler's own time).
    assert after[("autopilot_vehicle_goal_age_seconds_count", ())] == 1
    age = after[("autopilot_vehicle_goal_age_seconds_sum", ())]
    assert 0.05 <= age < 1.0
    assert after[("autopilot_vehicle_goal_age_seconds_bucket", (("le", "0.025"),))] == 0
    assert after[("autopilot_vehicle_goal_age_seconds_bucket", (("le", "+Inf"),))] == 1


def test_link_events_set_the_link_gauge_and_start_the_goal_age_afresh() -> None:
    metrics = VehicleMetrics()
    registry = metrics.registry
    # The events the agent emits as a link comes and goes.
    metrics.on_event(ev.LinkChanged(state="offer", relay="r", t=0.0))
    metrics.on_event(ev.LinkChanged(state="up", relay="r", t=1.0))
    assert registry.get_sample_value("autopilot_vehicle_link_up") == 1
    metrics.on_event(_goal(1, t=2.0))
    metrics.on_event(ev.ModeChanged(mode="manual", operator="ann", t=2.5))
    metrics.on_event(ev.LinkChanged(state="down", relay="r", reason="gone", t=3.0))
    assert registry.get_sample_value("autopilot_vehicle_link_up") == 0
    assert registry.get_sample_value("autopilot_vehicle_mode") == 0
    metrics.on_event(ev.LinkChanged(state="up", relay="r", t=10.0))
    metrics.on_event(_goal(1, t=11.0))
    # The first goal of the new link has no previous one: nothing observed across the outage.
    assert registry.get_sample_value("autopilot_vehicle_goal_age_seconds_count") == 0
    metrics.on_event(_goal(2, t=11.1))
    assert registry.get_sample_value("autopilot_vehicle_goal_age_seconds_count") == 1
    assert registry.get_sample_value("autopilot_vehicle_goal_age_seconds_sum") == pytest.approx(0.1)


def _goal(seq: int, t: float) -> ev.GoalApplied:
    return ev.GoalApplied(seq=seq, op="face", frame=None, x=10, y=100, w=W, h=H, t=t)
