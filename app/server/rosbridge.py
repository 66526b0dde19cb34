"""WebSocket ``/rosbridge`` and the simulated robot's state for the map (``GET`` its
simulation's ``state_path``), plus the tasks that step the robots and film their cameras.

The rules live in :mod:`app.rosbridge.protocol` and each robot's hub; :mod:`app.server.websocket`
moves the frames with the policy it shares with ``/ws`` (size limit, bounded outbox, JSON edge).
The server simulates one kind of robot (``autopilot serve --robot``, named by
:mod:`app.simulators`), which it knows only as a :class:`~app.rosbridge.simulated.Simulation`:
one robot for the whole server, or one per signaling room, made when a connection first names
the room (at most :data:`MAX_ROOMS` at once; the robots of rooms nobody is connected to make way
for new ones). A connection is bound to the room its token names (``auth``, or the handshake's
bearer token); with no access control, to the room its URL asks for (``/rosbridge?room=R``, else
the default room). A room's tokens reach only its robot.

Every tick each robot steps and each connection's writer is woken; a writer that is free then
takes its session's publications (the latest of each subscription), so the tick costs the same
whatever the clients subscribe to, and a client that does not read is sent nothing and slows no
one. The tick is the simulation's own: its robots advance that much per step, so pacing the loop
any other way would only change their speed. A robot's camera is
filmed at its own pace by a task of its own, rendered in a worker thread (one for every room, so
the renders of many rooms queue rather than take every core), and only while someone subscribes:
the tick never waits for a render.
"""

from __future__ import annotations

import asyncio
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Final

from fastapi import APIRouter, HTTPException, Request, WebSocket, status
from pydantic import TypeAdapter, ValidationError

from app.protocol.close_codes import CloseCode
from app.protocol.jsonedge import oversize
from app.protocol.rooms import DEFAULT_ROOM
from app.protocol.ros import DEFAULT_FLAVOUR, RosFlavour
from app.protocol.signaling import Name
from app.protocol.tokens import bearer_token
from app.rosbridge.protocol import Frame, Hub, Publish, Refused, RosbridgeSession, parse_frame
from app.rosbridge.protocol import status as rosbridge_status
from app.rosbridge.simulated import Camera, SimulatedRobot
from app.server.access import RosbridgeGate, bearer_claims
from app.server.config import Settings
from app.server.metrics import ServerMetrics
from app.server.websocket import (
    Outbox,
    Outboxes,
    SocketPolicy,
    client_address,
    login_deadline,
    refuse_if_full,
    serve,
)
from app.simulators import DEFAULT_SIMULATOR, SimulatorName, simulation

log = logging.getLogger(__name__)

router = APIRouter()

# If a tick or camera task falls this far behind the wall clock it skips ahead instead of
# catching up.
MAX_LAG_S: Final = 0.5
# At most this many rooms have a robot of their own: each steps every tick and may be filmed.
MAX_ROOMS: Final = 16
_ROOM_NAME: TypeAdapter[str] = TypeAdapter(Name)


class RoomsFull(Exception):
    """No robot can be made for another room."""


@dataclass
class Running:
    """A robot the server steps, and the task that films its camera (when it has one)."""

    robot: SimulatedRobot
    filming: asyncio.Task[None] | None = None


class Connection:
    """One ``/rosbridge`` connection: its outbox from the start, its session once it is bound
    to a room's robot."""

    def __init__(self) -> None:
        self.session: RosbridgeSession | None = None
        self.room: str | None = None

    def pull(self) -> list[Frame]:
        """The session's publications as frames, JSON or CBOR (none before it has a session)."""
        return [] if self.session is None else self.session.take_frames()


class Simulator:
    """The simulated robots, their rosbridge hubs, and the tasks that step and film them.

    Lives on ``app.state.simulator``.
    """

    def __init__(
        self,
        policy: SocketPolicy,
        max_sessions: int = 64,
        ros: RosFlavour = DEFAULT_FLAVOUR,
        robot: SimulatorName = DEFAULT_SIMULATOR,
        max_rooms: int = MAX_ROOMS,
    ) -> None:
        self.simulation = simulation(robot)
        self.ros: RosFlavour = ros
        self.max_rooms = max_rooms
        # The robot every room reaches, or None when each room has its own (in rooms).
        self.shared = None if self.simulation.per_room else Running(self.simulation.robot(ros))
        self.rooms: dict[str, Running] = {}
        self.tick_s = self.simulation.tick_s
        self.ticks = 0
        self.policy = policy
        self.outboxes: Outboxes[Connection] = Outboxes(policy, max_sessions)
        self._task: asyncio.Task[None] | None = None
        self._camera_thread: ThreadPoolExecutor | None = None

    @classmethod
    def from_settings(cls, settings: Settings) -> Simulator:
        """A fresh simulator of ``settings``' robot, with its socket policy and session cap."""
        return cls(
            SocketPolicy.from_settings(settings),
            settings.max_rosbridge_sessions,
            settings.ros,
            settings.robot,
        )

    @property
    def per_room(self) -> bool:
        """True when each room has a robot of its own."""
        return self.shared is None

    def start(self) -> None:
        """Start stepping the robots every ``tick_s`` of wall time (and filming the shared
        robot's camera, if it has one)."""
        self._task = asyncio.create_task(self._run(), name="simulator-tick")
        self._task.add_done_callback(_report_crash)
        if self.shared is not None:
            self._start_filming(self.shared, "camera")

    async def stop(self) -> None:
        """Stop the tick and camera tasks and wait for them."""
        tasks = [self._task, *(each.filming for each in self._running())]
        running = [task for task in tasks if task is not None]
        for task in running:
            task.cancel()
        await asyncio.gather(*running, return_exceptions=True)
        self._task = None
        if self._camera_thread is not None:
            self._camera_thread.shutdown(wait=True, cancel_futures=True)
            self._camera_thread = None

    def hub_for(self, room: str) -> Hub[Any]:
        """The hub of the robot ``room`` reaches (the shared robot's for every room), made when
        first asked for; ``RoomsFull`` when :attr:`max_rooms` rooms have one already and
        someone is connected to each."""
        if self.shared is not None:
            return self.shared.robot.hub
        running = self.rooms.get(room)
        if running is None:
            if len(self.rooms) >= self.max_rooms:
                self._free_unattended()
            if len(self.rooms) >= self.max_rooms:
                raise RoomsFull(f"at most {self.max_rooms} rooms have a simulated robot")
            running = self.rooms[room] = Running(self.simulation.robot(self.ros))
            self._start_filming(running, f"camera-{room}")
        return running.robot.hub

    def _free_unattended(self) -> None:
        """Forget the robots of the rooms nobody is connected to: a room that comes back later
        gets a new robot at its start, rather than rooms once used keeping out new ones."""
        for name, running in list(self.rooms.items()):
            if not running.robot.hub.sessions:
                if running.filming is not None:
                    running.filming.cancel()
                del self.rooms[name]
                log.info("room %r's robot freed: nobody is connected to it", name)

    def open(self, address: str = "local", waiting: bool = False) -> tuple[Connection, Outbox]:
        """A new rosbridge client from ``address``: its connection (not yet bound to a room)
        and outbox; ``waiting`` while it has shown no token (see
        :class:`~app.server.websocket.Outboxes`)."""
        connection = Connection()
        outbox = self.outboxes.open(connection, address, connection.pull, waiting)
        return connection, outbox

    def bind(self, connection: Connection, room: str) -> RosbridgeSession:
        """Give ``connection`` a session on ``room``'s robot; ``RoomsFull`` if it has none and
        can have none."""
        session = self.hub_for(room).open_session()
        connection.session, connection.room = session, room
        return session

    def forget(self, connection: Connection) -> None:
        """The client is gone: its subscriptions go with it."""
        if connection.session is not None:
            connection.session.close()
        self.outboxes.forget(connection)

    def state(self, room: str) -> dict[str, Any]:
        """What the map shows of the robot ``room`` reaches, JSON-ready; for a room whose robot
        is not made yet, a robot at its start (made for the answer, and kept by no one)."""
        running = self.shared or self.rooms.get(room)
        robot = self.simulation.robot(self.ros) if running is None else running.robot
        return robot.state()

    def tick(self) -> None:
        """One step of every robot, then a word to every writer that new messages are there."""
        now = time.monotonic()
        for running in self._running():
            running.robot.step(now)
        self.ticks += 1
        self.wake()

    def wake(self) -> None:
        """Tell every writer there may be something new to send (a tick, a publication)."""
        for _, outbox in self.outboxes.items():
            outbox.wake()

    def _running(self) -> list[Running]:
        """Every robot the server steps."""
        return [self.shared] if self.shared is not None else list(self.rooms.values())

    def _start_filming(self, running: Running, name: str) -> None:
        camera = running.robot.camera
        if camera is not None:
            running.filming = asyncio.create_task(self._film(camera), name=name)
            running.filming.add_done_callback(_report_crash)

    async def _run(self) -> None:
        next_at = time.monotonic()
        while True:
            self.tick()
            next_at += self.tick_s
            delay = next_at - time.monotonic()
            if delay < -MAX_LAG_S:
                log.warning("simulator tick %.0f ms late; skipping ahead", -delay * 1000)
                next_at = time.monotonic()
                delay = 0.0
            await asyncio.sleep(max(delay, 0.0))

    async def _film(self, camera: Camera) -> None:
        """Render and publish ``camera``'s frames at its frame rate while anyone subscribes."""
        loop = asyncio.get_running_loop()
        thread = self._camera()
        # Loaded in the camera thread, so that loading never holds up a tick.
        await loop.run_in_executor(thread, camera.prepare)
        period = 1.0 / camera.fps
        next_at = loop.time()
        while True:
            if camera.wanted():
                render, stamp = camera.shot(), time.time()
                jpeg = await loop.run_in_executor(thread, render)
                camera.publish(jpeg, stamp)
                self.wake()
            next_at += period
            delay = next_at - loop.time()
            if delay < -MAX_LAG_S:
                next_at = loop.time()
            await asyncio.sleep(max(delay, 0.0))

    def _camera(self) -> ThreadPoolExecutor:
        """The one thread every camera renders in, made for the first (a server whose robots
        carry none never has it)."""
        if self._camera_thread is None:
            self._camera_thread = ThreadPoolExecutor(1, thread_name_prefix="camera")
        return self._camera_thread


def _requested_room(websocket: WebSocket) -> str | None:
    """The room a connection without access control asks for (``?room=R``, else the default);
    None when the name is not a room's."""
    try:
        return _ROOM_NAME.validate_python(websocket.query_params.get("room", DEFAULT_ROOM))
    except ValidationError:
        return None


async def robot_state(request: Request) -> dict[str, Any]:
    """``GET`` the simulation's ``state_path``: what the client's map shows of the robot the
    room reaches -- the room its token names (a token of any role), or without access control
    the one ``?room=R`` names (else the default room)."""
    settings: Settings = request.app.state.settings
    asked = request.query_params.get("room")
    room = asked or DEFAULT_ROOM
    if settings.secret is not None:
        claims = bearer_claims(settings.secret, bearer_token(request.headers), time.time())
        if isinstance(claims, str):
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED, claims, {"WWW-Authenticate": "Bearer"}
            )
        if asked is not None and asked != claims.room:
            raise HTTPException(
                status.HTTP_403_FORBIDDEN, f"this token is for room {claims.room!r}, not {asked!r}"
            )
        room = claims.room
    simulator: Simulator = request.app.state.simulator
    return simulator.state(room)


@router.websocket("/rosbridge")
async def rosbridge(websocket: WebSocket) -> None:
    """One rosbridge v2 client (roslibpy, roslib.js): JSON text frames both ways."""
    simulator: Simulator = websocket.app.state.simulator
    metrics: ServerMetrics = websocket.app.state.metrics
    gate = RosbridgeGate(websocket.app.state.settings.secret)
    refusal = gate.handshake(bearer_token(websocket.headers), time.time())
    asked = _requested_room(websocket) if gate.secret is None else None
    if refusal is None and gate.secret is None and asked is None:
        refusal = "?room= names no room (1 to 64 printable characters)"
    if refusal is not None:
        log.info("rosbridge handshake refused: %s", refusal)
        metrics.refused("auth" if gate.secret is not None else "invalid")
        await websocket.close(CloseCode.POLICY_VIOLATION)  # before accept(): HTTP 403
        return
    await websocket.accept()
    if await refuse_if_full(websocket, simulator.outboxes, "rosbridge clients"):
        return

    def authenticated() -> bool:
        return gate.secret is None or gate.claims is not None

    connection, outbox = simulator.open(client_address(websocket), not authenticated())

    def session() -> RosbridgeSession | None:
        """The connection's session, bound on first need to the room its token (or URL)
        names; None while it has proved no token."""
        if connection.session is not None:
            return connection.session
        room = asked if gate.secret is None else gate.room
        if room is None:
            return None
        try:
            bound = simulator.bind(connection, room)
        except RoomsFull as exc:
            outbox.send(rosbridge_status("error", str(exc)))
            outbox.close(CloseCode.TRY_AGAIN_LATER, "no room for another robot")
            return None
        gate.bind(room if simulator.per_room else None)
        return bound

    session()  # bound at once when the room is known already

    def on_text(text: str) -> None:
        closing: tuple[int, str] | None = None
        if (reason := oversize(text, simulator.policy.max_message_bytes)) is not None:
            metrics.refused("invalid")
            replies = _errors(connection, reason)
        else:
            frame = parse_frame(text)
            decision = gate.check(frame, time.time())
            if decision.forward and isinstance(frame, Refused):
                metrics.refused("invalid")
            bound = session() if decision.forward else None
            replies = bound.handle(frame) if bound is not None else []
            if bound is not None and isinstance(frame, Publish):
                simulator.wake()  # a camera image goes out now, not at the next tick
            if decision.reply is not None:  # the gate replies only to refuse: no token, or a
                metrics.refused("auth")  # role that may not do this
                replies.append(decision.reply)
            closing = decision.close
            if decision.forward is False and closing is None:
                session()  # an auth op proved a token: bind now, not at the next frame
        if authenticated():
            simulator.outboxes.authenticated(connection)
        for reply in replies:
            outbox.send(reply)
        if closing is not None:
            outbox.close(*closing)  # after the refusal's reason

    def on_binary(_data: bytes) -> None:
        metrics.refused("invalid")
        for reply in _errors(connection, "binary frames are not supported: send JSON text"):
            outbox.send(reply)

    async def end_at_expiry() -> None:
        """Close the connection once its token has expired (a renewal moves the time on)."""
        while True:
            expires_at = gate.expires_at
            await asyncio.sleep(1.0 if expires_at is None else max(0.0, expires_at - time.time()))
            if (expired := gate.expiry(time.time())) is not None:
                metrics.refused("auth")
                assert expired.reply is not None and expired.close is not None
                outbox.send(expired.reply)
                outbox.close(*expired.close)
                return

    watchdog = None
    if gate.secret is not None:
        watchdog = asyncio.create_task(end_at_expiry(), name="rosbridge-expiry")
    try:
        deadline = login_deadline(simulator.policy, authenticated, "auth")
        await serve(websocket, outbox, on_text, on_binary, name="rosbridge", deadline=deadline)
    finally:
        if watchdog is not None:
            watchdog.cancel()
        simulator.forget(connection)


def _errors(connection: Connection, text: str) -> list[dict[str, Any]]:
    """The status error for a frame the adapter refused, by the session's rule once it has one."""
    if connection.session is not None:
        return connection.session.error(text)
    return [rosbridge_status("error", text)]


def _report_crash(task: asyncio.Task[None]) -> None:
    # Cancelling and gathering hides a task's own failure; log it here instead.
    if not task.cancelled() and (error := task.exception()) is not None:
        log.error("%s died", task.get_name(), exc_info=error)
