"""The vehicle agent: signaling, the link to the relay, goals to Twists, pose telemetry.

One :class:`Agent` runs until cancelled. It logs in as a vehicle, waits for a relay in the room,
offers to it and keeps that link alive: when the relay leaves, the link fails or the signaling
server goes away, the turtle gets a zero Twist and the agent reconnects with backoff, without
restarting. With a token it renews its session when the server says (``renew``), before the
token expires, and uses the fresh token from then on: for a later login, and on the server's
``/rosbridge``. Everything that happens is dispatched from one queue, one handler per event kind.

What to do with the relay's goals, stops, mode changes and drive commands, the turtle's poses
and the clock is the :class:`~vehicle_agent.pilot.Pilot`'s to decide; the agent feeds it (with
the time) and acts on its answers: publishes its Twists and logs its records.
"""

from __future__ import annotations

import asyncio
import logging
import math
import ssl
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field, replace
from typing import Any

from aiortc import MediaStreamTrack, RTCIceServer
from aiortc.contrib.media import MediaRelay
from pydantic import ValidationError

from app.protocol import channels, jsonedge
from app.protocol import events as ev
from app.protocol.channels import AUTOPILOT_CHANNEL
from app.protocol.control import for_robot, with_standoff
from app.protocol.errors import describe
from app.protocol.events import PilotEvent
from app.protocol.robot import TURTLESIM, Robot
from app.protocol.rooms import DEFAULT_ROOM
from app.protocol.signaling import Renew, Renewed
from app.supervise import Backoff
from vehicle_agent.capture_times import CaptureTimes
from vehicle_agent.control import PROFILES, SPAWN_THETA, Pose, Twist
from vehicle_agent.events import EventLog
from vehicle_agent.frame_times import FrameTimes
from vehicle_agent.peer import RelayLink
from vehicle_agent.pilot import Pilot
from vehicle_agent.robotlink import RobotLink, RobotLinkError
from vehicle_agent.signaling import SignalingClient, SignalingError

log = logging.getLogger(__name__)

# The relay must answer and ICE must connect within this long, or the agent offers again.
CONNECT_TIMEOUT_S = 10.0
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
    """The Python vehicle: streams ``video`` to the relay and drives ``turtle`` from goals."""

    def __init__(
        self,
        config: AgentConfig,
        video: MediaStreamTrack,
        turtle: RobotLink,
        events: EventLog | None = None,
    ) -> None:
        if config.profile not in PROFILES:
            raise ValueError(f"unknown profile {config.profile!r}; choose from {sorted(PROFILES)}")
        profile = PROFILES[config.profile]
        if config.goal_timeout_s is not None:
            profile = replace(profile, goal_timeout_s=config.goal_timeout_s)
        profile = for_robot(with_standoff(profile, config.standoff_m), config.robot)
        self.config = config
        self.video = video
        self.turtle = turtle
        self.events = events or EventLog()
        # The camera's frame times, so that a goal's bearing is taken at its frame's heading.
        self.frame_times = FrameTimes()
        self.events.listeners.append(self.frame_times.on_event)
        self.pilot = Pilot(profile, limits=config.robot.limits)
        self.pose: Pose | None = None
        self._first_pose: asyncio.Future[Pose] | None = None
        self._media = MediaRelay()
        self._link: RelayLink | None = None
        self._relay: str | None = None
        self._client: SignalingClient | None = None
        # The session's token as last renewed (the next login uses it), and the renewal's timer.
        self.token = config.token
        self._renewal: asyncio.TimerHandle | None = None
        self._queue: asyncio.Queue[tuple[str, Any]] = asyncio.Queue()
        self._link_backoff = Backoff()
        self._retry: asyncio.TimerHandle | None = None
        self._last_telemetry = 0.0
        # The camera's tagged frames (its frame_sent events), batched for the relay's clients.
        self._capture_times = CaptureTimes()
        self.events.listeners.append(self._on_event)
        self.logged_in = asyncio.Event()
        self._handlers: dict[str, Callable[[Any], Awaitable[None]]] = {
            "login": self._ignore,
            "peers": self._on_peers,
            "answer": self._on_answer,
            "candidate": self._on_candidate,
            "leave": self._on_leave,
            "renewed": self._on_renewed,
            "error": self._on_server_error,
        }
        # What the session loop's queue carries (besides "closed", which ends the session).
        self._events: dict[str, Callable[[Any], Awaitable[None]]] = {
            "signal": self._on_signal,
            "link_down": self._on_link_event,
            "retry": self._on_retry,
            "renew": self._on_renew,
        }
        # One handler per message the vehicle accepts on `autopilot` (channels.RECEIVERS).
        self._channel_handlers: dict[type[channels.ChannelMessage], ChannelHandler] = {
            channels.Goal: self._on_goal,
            channels.Stop: self._on_stop,
            channels.ModeChange: self._on_mode,
            channels.Drive: self._on_drive,
            channels.Error: self._on_peer_error,
        }

    def camera_tap(self) -> MediaStreamTrack:
        """Another reader of the camera, beside the relay's (the flight recorder's)."""
        return self._media.subscribe(self.video, buffered=False)

    @property
    def link(self) -> RelayLink | None:
        """The current connection to the relay, if any."""
        return self._link

    async def run(self) -> None:
        """Run until cancelled; raises :class:`SignalingError` if the first login fails."""
        self._first_pose = asyncio.get_running_loop().create_future()
        await self.turtle.start(self._on_pose)
        ticker = asyncio.create_task(self._tick(), name="control-tick")
        spawn = (
            asyncio.create_task(self._spawn_step(), name="spawn-step")
            if self.config.spawn_step and self.config.robot.turtlesim
            else None
        )
        try:
            await self._signaling_loop()
        finally:
            ticker.cancel()
            if spawn is not None:
                spawn.cancel()
            await self._drop_link("agent stopping")
            await self.turtle.close()
            self.video.stop()

    # --- signaling -----------------------------------------------------------------------

    async def _signaling_loop(self) -> None:
        backoff = Backoff()
        first = True
        while True:
            client = SignalingClient(
                self.config.server,
                self.config.name,
                self.config.room,
                token=self.token,
                tls=self.config.tls,
            )
            try:
                peers = await client.connect()
            except SignalingError as exc:
                # A wrong URL or a refused name at start-up is the operator's to fix; later
                # the server may just be restarting.
                if first:
                    raise
                delay = backoff.next()
                log.warning("%s; retrying in %.1f s", exc, delay)
                await asyncio.sleep(delay)
                continue
            first = False
            backoff.reset()
            log.info(
                "logged in to %s as vehicle %r in room %r", client.url, client.name, client.room
            )
            self._client = client
            self.logged_in.set()
            try:
                await self._session(client, peers)
            finally:
                self.logged_in.clear()
                self._client = None
                await self._drop_link("signaling connection lost")
                self._relay = None
                await client.close()
            delay = backoff.next()
            log.warning("signaling connection lost; reconnecting in %.1f s", delay)
            await asyncio.sleep(delay)

    async def _session(self, client: SignalingClient, peers: list[dict[str, Any]]) -> None:
        self._queue = asyncio.Queue()
        reader = asyncio.create_task(self._read(client), name="signaling-reader")
        self._renew_after(client.renew_in)
        try:
            await self._on_peers({"peers": peers})
            while True:
                kind, payload = await self._queue.get()
                if kind == "closed":
                    return
                await self._events[kind](payload)
        finally:
            reader.cancel()
            await asyncio.gather(reader, return_exceptions=True)
            if self._retry is not None:
                self._retry.cancel()
                self._retry = None
            if self._renewal is not None:
                self._renewal.cancel()
                self._renewal = None

    def _renew_after(self, seconds: float | None) -> None:
        """Ask for a fresh token in ``seconds`` (None: the server asks for no tokens)."""
        if seconds is None:
            return
        queue = self._queue
        loop = asyncio.get_running_loop()
        self._renewal = loop.call_later(seconds, queue.put_nowait, ("renew", None))

    async def _on_renew(self, payload: None) -> None:
        self._renewal = None
        if self._client is not None:
            await self._client.send(Renew(type="renew").model_dump(exclude_none=True))

    async def _on_renewed(self, message: dict[str, Any]) -> None:
        try:
            renewed = Renewed.model_validate(message)
        except ValidationError as exc:
            log.warning("malformed renewal from the server: %s", describe(exc))
            return
        self.token = renewed.token
        self.turtle.renew(renewed.token)
        log.debug("token renewed; next renewal in %.0f s", renewed.renewIn)
        self._renew_after(renewed.renewIn)

    async def _on_signal(self, message: dict[str, Any]) -> None:
        handler = self._handlers.get(message["type"])
        if handler is None:
            log.debug("ignoring signaling message %s", message["type"])
        else:
            await handler(message)

    async def _on_link_event(self, payload: tuple[RelayLink, str]) -> None:
        link, reason = payload
        await self._on_link_down(link, reason)

    async def _on_retry(self, payload: None) -> None:
        self._retry = None
        await self._ensure_link()

    async def _read(self, client: SignalingClient) -> None:
        async for message in client.messages():
            self._queue.put_nowait(("signal", message))
        self._queue.put_nowait(("closed", None))

    async def _ignore(self, message: dict[str, Any]) -> None:
        return None

    async def _on_peers(self, message: dict[str, Any]) -> None:
        relays = [p.get("name") for p in message.get("peers", []) if p.get("role") == "relay"]
        relay = relays[0] if relays and isinstance(relays[0], str) else None
        if relay == self._relay:
            return
        if self._relay is not None:
            log.info("relay %s left the room", self._relay)
            await self._drop_link("relay left")
        self._relay = relay
        self._link_backoff.reset()
        if relay is None:
            log.info("waiting for a relay in room %r", self.config.room)
        else:
            log.info("relay %s is in the room", relay)
            await self._ensure_link()

    async def _on_answer(self, message: dict[str, Any]) -> None:
        link = self._link
        if (
            link is None
            or message.get("from") != link.relay
            or not isinstance(message.get("sdp"), str)
        ):
            log.warning("ignoring an answer from %s", message.get("from"))
            return
        await link.on_answer(message["sdp"])

    async def _on_candidate(self, message: dict[str, Any]) -> None:
        link = self._link
        candidate = message.get("candidate")
        if link is None or message.get("from") != link.relay:
            log.debug("ignoring a candidate from %s", message.get("from"))
            return
        if candidate is not None and not isinstance(candidate, dict):
            log.warning("ignoring a malformed candidate from %s", message.get("from"))
            return
        await link.on_candidate(candidate)

    async def _on_leave(self, message: dict[str, Any]) -> None:
        if message.get("from") == self._relay:
            log.info("relay %s left", self._relay)
            await self._drop_link("relay left")
            self._relay = None

    async def _on_server_error(self, message: dict[str, Any]) -> None:
        log.warning("signaling server refused %s: %s", message.get("ref"), message.get("reason"))

    # --- the link to the relay -------------------------------------------------------------

    async def _ensure_link(self) -> None:
        if self._relay is None or self._link is not None or self._retry is not None:
            return
        client = self._client
        if client is None:
            return
        ice_servers = [
            RTCIceServer(urls=s.urls, username=s.username, credential=s.credential)
            for s in client.ice_servers
        ]
        link = RelayLink(
            self._relay,
            self._media.subscribe(self.video, buffered=False),
            client.send,
            self._on_channel_message,
            self._link_failed,
            ice_servers + self.config.ice_servers,
            client.ice_transport_policy,
        )
        link.on_up = self._on_link_up
        self._link = link
        self._act(self.pilot.new_link(time.monotonic()))
        self.events.emit(ev.LinkChanged(state="offer", relay=link.relay, t=time.monotonic()))
        await link.start()
        asyncio.get_running_loop().call_later(CONNECT_TIMEOUT_S, self._check_connected, link)

    def _on_link_up(self, link: RelayLink) -> None:
        candidates = link.local_candidate_types()
        log.info("link to %s up (local candidates: %s)", link.relay, ", ".join(candidates))
        self.events.emit(
            ev.LinkChanged(
                state="up",
                relay=link.relay,
                local_candidates=tuple(candidates),
                selected=link.selected_candidate_type(),
                t=time.monotonic(),
            )
        )

    def _check_connected(self, link: RelayLink) -> None:
        if link is self._link and not link.connected.is_set():
            self._link_failed(link, f"no connection within {CONNECT_TIMEOUT_S:g} s")

    def _link_failed(self, link: RelayLink, reason: str) -> None:
        self._queue.put_nowait(("link_down", (link, reason)))

    async def _on_link_down(self, link: RelayLink, reason: str) -> None:
        if link is not self._link:
            return  # an old link we already replaced
        await self._drop_link(reason)
        if self._relay is not None:
            delay = self._link_backoff.next()
            log.info("offering to %s again in %.1f s", self._relay, delay)
            self._retry = asyncio.get_running_loop().call_later(
                delay, self._queue.put_nowait, ("retry", None)
            )

    async def _drop_link(self, reason: str) -> None:
        link, self._link = self._link, None
        # Stop at once, autopilot or operator: the link that carried the commands is gone.
        self._act(self.pilot.halt(time.monotonic()))
        if link is None:
            return
        log.info("link to %s down: %s", link.relay, reason)
        self.events.emit(
            ev.LinkChanged(state="down", relay=link.relay, reason=reason, t=time.monotonic())
        )
        await link.close()

    # --- data channel ----------------------------------------------------------------------

    def _on_channel_message(self, link: RelayLink, text: str | bytes) -> None:
        if link is not self._link:
            return
        if not link.connected.is_set():
            link.connected.set()
        reply = self.handle_channel_message(text, link.relay)
        if reply is not None:
            link.send(reply)

    def handle_channel_message(self, text: str | bytes, relay: str) -> channels.Error | None:
        """Act on one data-channel message from ``relay``; returns the error reply, if any.

        Every frame goes through the JSON edge and the channel's models, so no input raises: it
        drives the turtle or is refused with a reason. Both channels to the relay accept what
        ``autopilot`` does (the state channel carries goals only).
        """
        try:
            data = jsonedge.loads(text)
        except jsonedge.JsonEdgeError as exc:
            return self._reject(relay, str(exc), None)
        message = channels.validate(data, AUTOPILOT_CHANNEL, "vehicle")
        if isinstance(message, channels.Refused):
            return self._reject(relay, message.reason, message.ref)
        self._channel_handlers[type(message)](relay, message)
        return None

    def _reject(self, relay: str, reason: str, ref: str | None) -> channels.Error:
        log.warning("dropped a data-channel message from %r: %s", relay, reason)
        return channels.Error(reason=reason, ref=ref)

    def _on_goal(self, relay: str, goal: channels.Goal) -> None:
        captured_at = self.frame_times.captured_at(goal.frame)
        self._act(self.pilot.goal(goal, time.monotonic(), captured_at))

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

    # --- the camera's capture times --------------------------------------------------------

    def _on_event(self, event: ev.AnyEvent) -> None:
        if not isinstance(event, ev.FrameSent):
            return
        # The event's clock is monotonic, which no other process can read; the clients compare
        # the capture time with their own wall clock.
        captured_ms = (time.time() - (time.monotonic() - event.t)) * 1000
        batch = self._capture_times.add(event.frame, captured_ms, event.t)
        if batch is not None and self._link is not None:
            # State, like pose: a lost batch is a few frames without a figure.
            self._link.send_state(batch)

    # --- turtle ------------------------------------------------------------------------------

    async def _spawn_step(self) -> None:
        """The thesis's spawn step (section 5.7.6): turn turtle1 to face "up" where it stands."""
        assert self._first_pose is not None
        pose = await self._first_pose
        try:
            await self.turtle.teleport(pose.x, pose.y, SPAWN_THETA)
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
            link = self._link
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
        """Carry out what the pilot did: publish its Twists, log its records, in order."""
        for event in done:
            if isinstance(event, ev.TwistSent):
                twist = Twist(event.linear, event.angular, event.seq, event.frame)
                self.turtle.publish(twist)
                if twist.is_zero and twist.seq is None:
                    log.info("turtle stopped")
            elif isinstance(event, ev.SearchStarted):
                log.info("target lost: searching to the %s", event.side)
            elif isinstance(event, ev.SearchEnded):
                log.info("search ended after %.1f s: %s", event.after_s, event.why)
            self.events.emit(event)
