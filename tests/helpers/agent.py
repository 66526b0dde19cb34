"""An agent with an in-process turtle and no network, for tests that call its handlers."""

from __future__ import annotations

from app.protocol.events import AnyEvent, TwistSent
from vehicle_agent.agent import Agent, AgentConfig
from vehicle_agent.core.control import Pose
from vehicle_agent.events import EventLog
from vehicle_agent.robotlink import SimLink
from vehicle_agent.video import FixedPath, SyntheticVideo

W, H = 320, 240


class Vehicle:
    """A real :class:`Agent` (never run) driving a :class:`SimLink`; records its events."""

    def __init__(self, profile: str) -> None:
        self.events: list[AnyEvent] = []
        log = EventLog()
        log.listeners.append(self.events.append)
        self.turtle = SimLink()
        video = SyntheticVideo(W, H, fps=15, path=FixedPath(0.5, 0.5))
        self.agent = Agent(
            AgentConfig(server="http://127.0.0.1:9", profile=profile), video, self.turtle, log
        )
        # The turtle's pose, as its first pose update would give it.
        self.agent.pilot.pose(Pose(5.5, 5.5, 0.0), 0.0)

    def twists(self) -> list[TwistSent]:
        return [e for e in self.events if isinstance(e, TwistSent)]
