"""The vehicle agent: the wiring between its signaling session, its pilot, its robot and its camera.

One :class:`Agent` runs until cancelled. Its :class:`~vehicle_agent.session.SignalingSession`
logs in, finds the relay and keeps the link to it (reconnecting, renewing the token); what the
relay says on that link, the robot's poses and the clock go to the
:class:`~vehicle_agent.core.pilot.Pilot`, which decides; the agent acts on its answers
(publishes its Twists, logs its records) and sends the relay the robot's pose and the camera's
capture times.
"""

from __future__ import annotations

import asyncio
import logging
import math
import ssl
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from aiortc import MediaStreamTrack, RTCIceServer
from aiortc.contrib.media import MediaRelay

from app.protocol import channels
from app.protocol import events as ev
from app.protocol.channels import AUTOPILOT_CHANNEL
from app.protocol.control import with_standoff
from app.protocol.events import PilotEvent
from app.protocol.robot import TURTLESIM, Robot
from app.protocol.rooms import DEFAULT_ROOM
from vehicle_agent.core.capture_times import CaptureTimes
from vehicle_agent.core.control import PROFILES, SPAWN_THETA, Pose
from vehicle_agent.core.pilot import Pilot
from vehicle_agent.events import EventLog
from vehicle_agent.peer import RelayLink
from vehicle_agent.robotlink import RobotLink, RobotLinkError
from vehicle_agent.session import SignalingSession

log = logging.getLogger(__name__)

TELEMETRY_PERIOD_S = 0.1

# Handles one validated data-channel message from the relay.
ChannelHandler = Callable[[str, Any], None]


@dataclass
class AgentConfig:
    """What ``autopilot vehicle`` was asked to do."""

    server: str
    room: str = DEFAULT_ROOM
    name: str = "vehicle"
    profile: str = "default"
    goal_timeout_s: float | None = None
    # The follow profile's distance from the target (None: the profile's own).
    standoff_m: float | None = None
    # Turn the turtle to face "up" (θ = π/2) at start, as the thesis's vehicle does (a
    # turtlesim only: no other robot has teleport_absolute).
    spawn_step: bool = True
    # The robot driven: its limits, its camera's field of view (the onboard law's), and whether
    # it is a turtlesim (``--robot``).
    robot: Robot = TURTLESIM
    ice_servers: list[RTCIceServer] = field(default_factory=list)
    # A vehicle token for the room (``autopilot token``), when the server asks for one.
    token: str | None = None
    # Trust for an https:// server: None means the system's CAs.
    tls: ssl.SSLContext | None = None


class Agent:
    """The Python vehicle: streams ``video`` to the relay and drives the robot through
    ``robot_link`` from goals."""

    def __init__(
        self,
        config: AgentConfig,
        video: MediaStreamTrack,
        robot_link: RobotLink,
        events: EventLog | None = None,
    ) -> None:
        if config.profile not in PROFILES:
            raise ValueError(f"unknown profile {config.profile!r}; choose from {sorted(PROFILES)}")
        profile = PROFILES[config.profile]
        if config.goal_timeout_s is not None:
            profile = replace(profile, goal_timeout_s=config.goal_timeout_s)
        self.config = config
        self.video = video
        self.robot_link = robot_link
        self.events = events or EventLog()
        self.pilot = Pilot(with_standoff(profile, config.standoff_m), robot=config.robot)
        self.pose: Pose | None = None
        self._first_pose: asyncio.Future[Pose] | None = None
        self._media = MediaRelay()
        self.session = SignalingSession(
            config.server,
            config.name,
            config.room,
            track=self.camera_tap,
            on_message=self.handle_channel_message,
            on_new_link=lambda: self._act(self.pilot.new_link(time.monotonic())),
            on_link_lost=lambda: self._act(self.pilot.halt(time.monotonic())),
            events=self.events,
            token=config.token,
            tls=config.tls,
            ice_servers=config.ice_servers,
        )
        # The robot's rosbridge connection (the camera's too) proves each renewed token.
        self.session.token_renewed.append(robot_link.renew)
        self.logged_in = self.session.logged_in
        self._last_telemetry = 0.0
        # The camera's tagged frames (its frame_sent events), batched for the relay's clients.
        self._capture_times = CaptureTimes()
        self.events.listeners.append(self._on_event)
        # One handler per message the vehicle accepts on `autopilot` (channels.RECEIVERS).
        self._channel_handlers: dict[type[channels.ChannelMessage], ChannelHandler] = {
            channels.Goal: self._on_goal,
            channels.Stop: self._on_stop,
            channels.ModeChange: self._on_mode,
            channels.Drive: self._on_drive,
            channels.Error: self._on_peer_error,
        }

    def camera_tap(self) -> MediaStreamTrack:
        """Another reader of the camera (the relay link's, the flight recorder's)."""
        return self._media.subscribe(self.video, buffered=False)

    @property
    def link(self) -> RelayLink | None:
        """The current connection to the relay, if any."""
        return self.session.link

    @property
    def token(self) -> str | None:
        """The session's token as last renewed."""
        return self.session.token

    async def run(self) -> None:
        """Run until cancelled; raises :class:`SignalingError` if the first login fails."""
        self._first_pose = asyncio.get_running_loop().create_future()
        await self.robot_link.start(self._on_pose)
        ticker = asyncio.create_task(self._tick(), name="control-tick")
        spawn = (
            asyncio.create_task(self._spawn_step(), name="spawn-step")
            if self.config.spawn_step and self.config.robot.turtlesim
            else None
        )
        try:
            await self.session.run()
        finally:
            ticker.cancel()
            if spawn is not None:
                spawn.cancel()
            await self.robot_link.close()
            self.video.stop()

    # --- data channel ----------------------------------------------------------------------

    def handle_channel_message(self, text: str | bytes, relay: str) -> channels.Error | None:
        """Act on one data-channel message from ``relay``; returns the error reply, if any.

        Every frame goes through the JSON edge and the channel's models, so no input raises: it
        drives the robot or is refused with a reason. Both channels to the relay accept what
        ``autopilot`` does (the state channel carries goals only).
        """
        message = channels.parse(text, AUTOPILOT_CHANNEL, "vehicle")
        if isinstance(message, channels.Refused):
            log.warning("dropped a data-channel message from %r: %s", relay, message.reason)
            return channels.Error(reason=message.reason, ref=message.ref)
        self._channel_handlers[type(message)](relay, message)
        return None

    def _on_goal(self, relay: str, goal: channels.Goal) -> None:
        self._act(self.pilot.goal(goal, time.monotonic()))

    def _on_stop(self, relay: str, message: channels.Stop) -> None:
        log.info("piloting stopped by %r", relay)
        self._act(self.pilot.stop(time.monotonic()))

    def _on_mode(self, relay: str, message: channels.ModeChange) -> None:
        done = self.pilot.mode_change(message.mode, message.operator, time.monotonic())
        if done:
            log.info(
                "mode %s%s (%s)",
                message.mode,
                f" by {message.operator}" if message.operator else "",
                message.reason or relay,
            )
        self._act(done)

    def _on_drive(self, relay: str, message: channels.Drive) -> None:
        now = time.monotonic()
        self._act(self.pilot.drive(message.seq, message.linear, message.angular, now))

    def _on_peer_error(self, relay: str, message: channels.Error) -> None:
        log.warning("%r reported an error: %r", relay, message.reason)

    # --- the camera's frames ----------------------------------------------------------------

    def _on_event(self, event: ev.AnyEvent) -> None:
        if not isinstance(event, ev.FrameSent):
            return
        self.pilot.frame(event.frame, event.t)
        # The event's clock is monotonic, which no other process can read; the clients compare
        # the capture time with their own wall clock.
        captured_ms = (time.time() - (time.monotonic() - event.t)) * 1000
        batch = self._capture_times.add(event.frame, captured_ms, event.t)
        link = self.session.link
        if batch is not None and link is not None:
            # State, like pose: a lost batch is a few frames without a figure.
            link.send_state(batch)

    # --- the robot ---------------------------------------------------------------------------

    async def _spawn_step(self) -> None:
        """The thesis's spawn step (section 5.7.6): turn turtle1 to face "up" where it stands."""
        assert self._first_pose is not None
        pose = await self._first_pose
        try:
            await self.robot_link.teleport(pose.x, pose.y, SPAWN_THETA)
        except RobotLinkError as exc:
            # The robot may not offer teleport_absolute; driving works without the step.
            log.warning("spawn step failed: %s", exc)
            self.events.emit(ev.SpawnStep(ok=False, reason=str(exc), t=time.monotonic()))
            return
        log.info("spawn step: turtle turned to θ = %.4f rad", SPAWN_THETA)
        self.events.emit(
            ev.SpawnStep(ok=True, x=pose.x, y=pose.y, theta=SPAWN_THETA, t=time.monotonic())
        )

    def _on_pose(self, pose: Pose) -> None:
        self.pose = pose
        if self._first_pose is not None and not self._first_pose.done():
            self._first_pose.set_result(pose)
        now = time.monotonic()
        self._act(self.pilot.pose(pose, now))
        if now - self._last_telemetry >= TELEMETRY_PERIOD_S:
            self._last_telemetry = now
            link = self.session.link
            sent = False
            if link is not None and all(map(math.isfinite, (pose.x, pose.y, pose.theta))):
                # Pose is state: the lossy channel, where a late one is skipped, not waited for.
                age_s = self.pilot.goal_age(now)
                age = None if age_s is None else age_s * 1000
                sent = link.send_state(
                    channels.Pose(
                        x=pose.x,
                        y=pose.y,
                        theta=pose.theta,
                        t=time.time() * 1000,
                        goalAgeMs=age,
                        search=self.pilot.search,
                    )
                )
            self.events.emit(ev.PoseReport(x=pose.x, y=pose.y, theta=pose.theta, sent=sent, t=now))

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(self.pilot.next_tick(time.monotonic()))
            self._act(self.pilot.tick(time.monotonic()))

    def _act(self, done: list[PilotEvent]) -> None:
        """Carry out what the pilot did: publish its Twists, then log its records in order."""
        # The robot first: the records' listeners (the recorder, the Foxglove view, the metrics)
        # run here, on the loop, and a goal's record comes before its Twist's: their work must
        # not delay the Twist.
        for event in done:
            if isinstance(event, ev.TwistSent):
                self.robot_link.publish(event.linear, event.angular)
        for event in done:
            if isinstance(event, ev.TwistSent):
                if event.linear == event.angular == 0.0 and event.seq is None:
                    log.info("robot stopped")
            elif isinstance(event, ev.SearchStarted):
                log.info("target lost: searching to the %s", event.side)
            elif isinstance(event, ev.SearchEnded):
                log.info("search ended after %.1f s: %s", event.after_s, event.why)
            self.events.emit(event)
