"""Data-channel input to the agent's real handler: goals, and the relay's ``mode`` and ``drive``
(the manual override), hostile input refused with a reason, never a command. No WebRTC needed:
the handler is called the way the data channel calls it."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from app.protocol.events import AnyEvent, GoalApplied, GoalDropped
from tests.helpers.agent import H, Vehicle, W
from vehicle_agent.core.control import PROFILES, Controller, Goal, Pose, angular_command


@pytest.fixture(scope="module", params=sorted(PROFILES))
def vehicles(request: pytest.FixtureRequest) -> Vehicle:
    # One per profile: building the video source takes seconds on a loaded machine.
    return Vehicle(request.param)


@pytest.fixture
def vehicle(vehicles: Vehicle) -> Iterator[Vehicle]:
    # Every case sends seq 1 again: a fresh link, as far as the latest-wins rule is concerned.
    vehicles.agent.pilot.new_link(0.0)
    vehicles.events.clear()
    yield vehicles


GOAL = '{"type": "goal", "seq": 1, "op": "face", "x": %s, "y": 100, "w": 320, "h": 240, "t": 0}'

HOSTILE: dict[str, str | bytes] = {
    "NaN literal": GOAL % "NaN",
    "Infinity literal": GOAL % "Infinity",
    '"nan" string': GOAL % '"nan"',
    '"inf" string': GOAL % '"inf"',
    "1e999": GOAL % "1e999",
    "5000-digit integer": GOAL % ("9" * 5000),
    "3000-deep nesting": "[" * 3000 + "]" * 3000,
    "invalid UTF-8": b'{"type": "goal\xff"}',
    "frame of 1e9 pixels": GOAL.replace('"w": 320', '"w": 1000000000') % "10",
    "not an object": "[1, 2]",
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_hostile_goals_get_an_error_and_never_drive_the_turtle(vehicle: Vehicle, case: str) -> None:
    reply = vehicle.agent.handle_channel_message(HOSTILE[case], "relay")
    assert reply is not None and reply.type == "error" and reply.reason
    assert vehicle.twists() == []
    # The handler still works: a good goal is taken.
    assert vehicle.agent.handle_channel_message(GOAL % "10", "relay") is None
    assert [e.x for e in vehicle.events if isinstance(e, GoalApplied)] == [10]
    vehicle.turtle.sim.step()
    pose = vehicle.turtle.sim.pose("turtle1")
    assert all(math.isfinite(v) for v in (pose.x, pose.y, pose.theta))


def test_a_nan_goal_in_the_controller_holds_still_in_both_profiles() -> None:
    for profile in PROFILES.values():
        controller = Controller(profile)
        controller.pose(Pose(5.5, 5.5, 0.0), 100.0)
        twist = controller.goal(Goal(math.nan, 10.0, W, H, 1), 100.0) or controller.pose(
            Pose(5.5, 5.5, 0.0), 100.0
        )
        assert twist is not None and math.isfinite(twist.angular_z), profile.name
        assert twist.angular_z == 0.0
        assert math.isfinite(angular_command(math.pi, profile))


MANUAL_GOAL = (
    '{"type": "goal", "seq": %d, "op": "face", "x": 10, "y": 100, "w": 320, "h": 240, "t": 0}'
)


def test_the_agent_ignores_goals_while_manual_and_drives_on_commands() -> None:
    vehicle = Vehicle("default")
    agent = vehicle.agent
    assert agent.handle_channel_message(MANUAL_GOAL % 1, "relay") is None
    assert vehicle.twists()[-1].angular != 0  # the autopilot steers
    take = '{"type": "mode", "mode": "manual", "operator": "ann", "reason": "taken over by ann"}'
    assert agent.handle_channel_message(take, "relay") is None
    assert (vehicle.twists()[-1].linear, vehicle.twists()[-1].angular) == (0.0, 0.0)
    before = len(vehicle.twists())
    assert agent.handle_channel_message(MANUAL_GOAL % 2, "relay") is None
    assert len(vehicle.twists()) == before
    assert vehicle.events[-1] == GoalDropped(
        seq=2, frame=None, why="manual", t=vehicle.events[-1].t
    )
    drive = '{"type": "drive", "seq": 1, "linear": 0, "angular": 1}'
    assert agent.handle_channel_message(drive, "relay") is None
    assert vehicle.twists()[-1].angular == PROFILES["default"].manual_angular
    # Hostile drive commands are refused with a reason and never move the turtle.
    for bad in (
        '{"type": "drive", "seq": 2, "linear": 2, "angular": 0}',
        '{"type": "drive", "seq": 0, "linear": 0, "angular": 0}',
        '{"type": "drive", "seq": 2, "linear": NaN, "angular": 0}',
        '{"type": "mode", "mode": "turbo"}',
    ):
        reply = agent.handle_channel_message(bad, "relay")
        assert reply is not None and reply.type == "error" and reply.reason, bad
    assert vehicle.twists()[-1].angular == PROFILES["default"].manual_angular
    back = '{"type": "mode", "mode": "auto"}'
    assert agent.handle_channel_message(back, "relay") is None
    assert (vehicle.twists()[-1].linear, vehicle.twists()[-1].angular) == (0.0, 0.0)
    assert agent.handle_channel_message(MANUAL_GOAL % 3, "relay") is None
    assert vehicle.twists()[-1].angular != 0  # goals steer again


def test_a_goals_twist_is_published_before_any_listener_hears_of_the_goal(
    vehicle: Vehicle, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The event log's listeners (the recorder, the Foxglove view) run on the agent's loop:
    whatever they do with a goal's record, its Twist is on its way to the robot already."""
    published: list[tuple[float, float]] = []
    monkeypatch.setattr(vehicle.turtle, "publish", lambda *twist: published.append(twist))
    heard: list[int] = []

    def listener(event: AnyEvent) -> None:
        if isinstance(event, GoalApplied):
            heard.append(len(published))

    vehicle.agent.events.listeners.append(listener)
    try:
        assert vehicle.agent.handle_channel_message(GOAL % "10", "relay") is None
    finally:
        vehicle.agent.events.listeners.remove(listener)
    # One goal, one Twist toward it, published before the goal's record was heard.
    [twist] = vehicle.twists()
    assert published == [(twist.linear, twist.angular)]
    assert heard == [1]
