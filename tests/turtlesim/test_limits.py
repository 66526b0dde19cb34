"""Caps and finite numbers in the simulator and the rosbridge session (issue 9 "Hostile input")."""

from __future__ import annotations

import json
import math
import sys
from typing import Any

import pytest

from app.rosbridge.protocol import (
    MAX_QUEUE_LENGTH,
    MAX_SUBSCRIPTIONS,
    MAX_THROTTLE_RATE_MS,
    RosbridgeSession,
)
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import MAX_CANVAS_POINTS, MAX_NAME_LENGTH, MAX_TURTLES, TurtleSim

LARGEST = sys.float_info.max


def call(session: RosbridgeSession, service: str, **args: Any) -> dict[str, Any]:
    replies = session.receive(json.dumps({"op": "call_service", "service": service, "args": args}))
    (response,) = [r for r in replies if r["op"] == "service_response"]
    return response


def in_range(theta: float) -> bool:
    return -math.pi <= theta < math.pi


# -- the simulator -----------------------------------------------------------------------------


def test_teleport_absolute_with_a_huge_angle_stays_in_range() -> None:
    sim = TurtleSim()
    for theta in (1e308, -1e308, LARGEST, 1e16, 7 * math.pi, -math.pi):
        sim.teleport_absolute("turtle1", 1.0, 1.0, theta)
        assert in_range(sim.pose("turtle1").theta), theta


def test_teleport_relative_with_the_largest_float_keeps_the_turtle_finite_and_inside() -> None:
    sim = TurtleSim()
    sim.teleport_relative("turtle1", LARGEST, LARGEST)
    sim.teleport_relative("turtle1", -LARGEST, -LARGEST)
    pose = sim.pose("turtle1")
    assert 0 <= pose.x <= sim.WORLD_SIZE and 0 <= pose.y <= sim.WORLD_SIZE
    assert in_range(pose.theta)
    for stroke in sim.strokes():
        assert all(math.isfinite(v) for point in stroke.points for v in point)


def test_huge_velocities_keep_every_pose_finite() -> None:
    sim = TurtleSim(clock=lambda: 0.0)
    sim.cmd_vel("turtle1", LARGEST, LARGEST)
    for _ in range(5):
        sim.step()
    pose = sim.pose("turtle1")
    assert all(math.isfinite(v) for v in (pose.x, pose.y, pose.theta)) and in_range(pose.theta)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_numbers_are_refused(bad: float) -> None:
    sim = TurtleSim()
    for action in (
        lambda: sim.cmd_vel("turtle1", bad, 0.0),
        lambda: sim.teleport_absolute("turtle1", 1.0, 1.0, bad),
        lambda: sim.teleport_relative("turtle1", bad, 0.0),
        lambda: sim.spawn(bad, 1.0, 0.0),
    ):
        with pytest.raises(ValueError, match="finite"):
            action()


def test_turtles_are_capped_in_number_and_name_length() -> None:
    sim = TurtleSim()
    with pytest.raises(ValueError, match="longer"):
        sim.spawn(1.0, 1.0, 0.0, "t" * (MAX_NAME_LENGTH + 1))
    for _ in range(2000):
        try:
            sim.spawn(1.0, 1.0, 0.0)
        except ValueError as exc:
            assert "at most" in str(exc)
    assert len(sim.names()) == MAX_TURTLES
    sim.kill("turtle1")
    assert sim.spawn(1.0, 1.0, 0.0, "again") == "again"  # room again after a kill


def test_killed_turtles_strokes_are_trimmed_too() -> None:
    sim = TurtleSim()
    for n in range(20):
        name = sim.spawn(0.5, 0.5, 0.0, f"t{n}")
        for i in range(5000):  # a zigzag: every move adds a point
            sim.teleport_absolute(name, 0.5 + (i % 2) * 0.5, 0.5 + (i % 3) * 0.5, 0.0)
        sim.step()  # teleports are queued; the tick applies (and draws) them in order
        sim.kill(name)
    points = sum(len(s.points) for s in sim.strokes())
    assert points <= MAX_CANVAS_POINTS
    # The newest drawing is what stays.
    assert sim.strokes()[-1].turtle == "t19"
    # turtle1 still draws from where it is.
    sim.teleport_absolute("turtle1", 2.0, 2.0, 0.0)
    sim.step()
    own = [s for s in sim.strokes() if s.turtle == "turtle1"]
    assert own[-1].points[-1] == (2.0, 2.0)


# -- the rosbridge session ---------------------------------------------------------------------


@pytest.fixture
def hub() -> RosbridgeHub:
    return RosbridgeHub(TurtleSim())


@pytest.fixture
def session(hub: RosbridgeHub) -> RosbridgeSession:
    opened = hub.open_session()
    # Refusals come back as `status` messages only to a client that asked for them.
    assert opened.receive(json.dumps({"op": "set_level", "level": "error"})) == []
    return opened


def subscribe(session: RosbridgeSession, **fields: Any) -> list[dict[str, Any]]:
    return session.receive(json.dumps({"op": "subscribe", "topic": "/turtle1/pose", **fields}))


def test_subscriptions_per_client_are_capped(session: RosbridgeSession) -> None:
    for n in range(MAX_SUBSCRIPTIONS):
        assert subscribe(session, id=f"s{n}") == []
    (error,) = subscribe(session, id="one-too-many")
    assert error["level"] == "error" and "at most" in error["msg"]
    assert subscribe(session, id="s0", throttle_rate=10) == []  # re-subscribing an id is fine


@pytest.mark.parametrize(
    "fields",
    [
        {"queue_length": MAX_QUEUE_LENGTH + 1},
        {"queue_length": 10**18},
        {"throttle_rate": MAX_THROTTLE_RATE_MS + 1},
        {"throttle_rate": 1e308},
    ],
)
def test_queue_length_and_throttle_rate_are_bounded(
    session: RosbridgeSession, fields: dict[str, Any]
) -> None:
    (error,) = subscribe(session, id="s", **fields)
    assert error["level"] == "error" and next(iter(fields)) in error["msg"]
    assert session.subscribed_topics() == []


def test_teleport_services_with_extreme_floats_answer_and_keep_theta_in_range(
    hub: RosbridgeHub, session: RosbridgeSession
) -> None:
    assert call(session, "/turtle1/teleport_relative", linear=LARGEST, angular=LARGEST)["result"]
    assert call(session, "/turtle1/teleport_absolute", x=1.0, y=1.0, theta=1e308)["result"]
    assert in_range(hub.sim.pose("turtle1").theta)


def test_spawn_over_the_cap_is_a_failed_call_not_a_crash(session: RosbridgeSession) -> None:
    results = [call(session, "/spawn", x=1.0, y=1.0)["result"] for _ in range(MAX_TURTLES + 5)]
    assert results.count(True) == MAX_TURTLES - 1  # turtle1 was already there
    assert call(session, "/spawn", name="x" * 500)["result"] is False
