"""WebSocket ``/rosbridge``, ``GET /turtlesim/state`` and ``GET /room/state``, plus the tasks that
step the simulated robots and film their cameras.

The rules live in :mod:`app.rosbridge.protocol` and each robot's hub; :mod:`app.server.websocket`
moves the frames with the policy it shares with ``/ws`` (size limit, bounded outbox, JSON edge).
The server simulates one kind of robot (``autopilot serve --robot``): turtlesim's turtles, one
simulator for the whole server, or the differential-drive robot of :mod:`app.diffdrive`, one per
signaling room, made when a connection first names the room (at most :data:`MAX_ROOMS` at once;
the robots of rooms nobody is connected to make way for new ones). A connection is bound to the room
its token names (``auth``, or the handshake's bearer token); with no access control, to the room
its URL asks for (``/rosbridge?room=R``, else the default room). A room's tokens reach only its
robot.

Every tick each robot steps and each connection's writer is woken; a writer that is free then
takes its session's publications (the latest of each subscription), so the tick costs the same
whatever the clients subscribe to, and a client that does not read is sent nothing and slows no
one. The tick is fixed at 16 ms (turtlesim's own): the simulators advance that much per step, so
pacing the loop any other way would only change the robots' speed. A robot's camera is filmed
at its own pace by a task of its own, rendered in a worker thread (one for every room, so the
renders of many rooms queue rather than take every core), and only while someone subscribes:
the tick never waits for a render.
"""

from __future__ import annotations

import asyncio
import logging
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from typing import TYPE_CHECKING, Any, Final

from fastapi import APIRouter, HTTPException, Request, WebSocket, status
from pydantic import TypeAdapter, ValidationError

from app.diffdrive.robot import CAMERA_HFOV
from app.diffdrive.roommap import STATE_PATH, room_state
from app.diffdrive.rosbridge import DiffDriveHub
from app.diffdrive.sim import RoomSim, Scene
from app.protocol.close_codes import CloseCode
from app.protocol.jsonedge import oversize
from app.protocol.page import to_json
from app.protocol.rooms import DEFAULT_ROOM
from app.protocol.ros import DEFAULT_FLAVOUR, RosFlavour
from app.protocol.signaling import Name
from app.rosbridge.protocol import Frame, Hub, Publish, Refused, RosbridgeSession, parse_frame
from app.rosbridge.protocol import status as rosbridge_status
from app.server.access import RosbridgeGate, bearer_claims, bearer_token, state_refusal
from app.server.config import Settings, SimulatedRobot
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
from app.turtlesim.rosbridge import RosbridgeHub
from app.turtlesim.sim import TurtleSim

if TYPE_CHECKING:
    from app.diffdrive.camera import Renderer

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


class TurtleRobot:
    """turtlesim: one simulator for every room."""

    def __init__(self, ros: RosFlavour) -> None:
        self.sim = TurtleSim()
        self.hub = RosbridgeHub(self.sim, ros)

    def step(self, now: float) -> None:
        """One tick of the simulator, then of its hub."""
        self.sim.step()
        self.hub.tick(now)


class RoomRobot:
    """One room's differential-drive robot, its hub, and the task that films its camera."""

    def __init__(self, ros: RosFlavour) -> None:
        self.sim = RoomSim()
        self.hub = DiffDriveHub(self.sim, ros)
        self.filming: asyncio.Task[None] | None = None

    def step(self, now: float) -> None:
        """One tick of the room, then of its hub."""
        self.sim.step()
        self.hub.tick(now)


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

    Lives on ``app.state.simulator``; with turtlesim, ``app.state.turtlesim`` is its
    :class:`TurtleSim`.
    """

    def __init__(
        self,
        policy: SocketPolicy,
        max_sessions: int = 64,
        ros: RosFlavour = DEFAULT_FLAVOUR,
        robot: SimulatedRobot = "turtlesim",
        max_rooms: int = MAX_ROOMS,
    ) -> None:
        self.robot: SimulatedRobot = robot
        self.ros: RosFlavour = ros
        self.max_rooms = max_rooms
        self.turtle = TurtleRobot(ros) if robot == "turtlesim" else None
        self.rooms: dict[str, RoomRobot] = {}
        self.tick_s = TurtleSim.TICK_S
        self.ticks = 0
        self.policy = policy
        self.outboxes: Outboxes[Connection] = Outboxes(policy, max_sessions)
        self._task: asyncio.Task[None] | None = None
        self._camera_thread: ThreadPoolExecutor | None = None
        self._renderer: asyncio.Future[Renderer] | None = None

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
    def sim(self) -> TurtleSim:
        """turtlesim's simulator; ``AttributeError`` when the server simulates another robot."""
        return self._turtle().sim

    @property
    def hub(self) -> RosbridgeHub:
        """turtlesim's hub; ``AttributeError`` when the server simulates another robot."""
        return self._turtle().hub

    def _turtle(self) -> TurtleRobot:
        if self.turtle is None:
            raise AttributeError(f"the server simulates {self.robot}, not turtlesim")
        return self.turtle

    def start(self) -> None:
        """Start stepping the robots every ``tick_s`` of wall time."""
        self._task = asyncio.create_task(self._run(), name="simulator-tick")
        self._task.add_done_callback(_report_crash)

    async def stop(self) -> None:
        """Stop the tick and camera tasks and wait for them."""
        tasks = [self._task, *(robot.filming for robot in self.rooms.values())]
        running = [task for task in tasks if task is not None]
        for task in running:
            task.cancel()
        await asyncio.gather(*running, return_exceptions=True)
        self._task = None
        if self._camera_thread is not None:
            self._camera_thread.shutdown(wait=True, cancel_futures=True)
            self._camera_thread = None

    def hub_for(self, room: str) -> Hub[Any]:
        """The hub of ``room``'s robot (turtlesim's for every room), made when first asked
        for; ``RoomsFull`` when :attr:`max_rooms` rooms have one already and someone is
        connected to each."""
        if self.turtle is not None:
            return self.turtle.hub
        robot = self.rooms.get(room)
        if robot is None:
            if len(self.rooms) >= self.max_rooms:
                self._free_unattended()
            if len(self.rooms) >= self.max_rooms:
                raise RoomsFull(f"at most {self.max_rooms} rooms have a simulated robot")
            robot = self.rooms[room] = RoomRobot(self.ros)
            robot.filming = asyncio.create_task(self._film(robot), name=f"camera-{room}")
            robot.filming.add_done_callback(_report_crash)
        return robot.hub

    def _free_unattended(self) -> None:
        """Forget the robots of the rooms nobody is connected to: a room that comes back later
        gets a new robot at its start, rather than rooms once used keeping out new ones."""
        for name, robot in list(self.rooms.items()):
            if not robot.hub.sessions:
                if robot.filming is not None:
                    robot.filming.cancel()
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

    def state(self) -> dict[str, Any]:
        """The turtles' poses and pens and the pen strokes, as JSON-ready data."""
        sim = self.sim
        turtles = [
            {"name": name, **asdict(sim.pose(name)), "pen": asdict(sim.pen(name))}
            for name in sim.names()
        ]
        strokes = [
            {"turtle": s.turtle, "pen": asdict(s.pen), "points": s.points} for s in sim.strokes()
        ]
        return {
            "world_size": TurtleSim.WORLD_SIZE,
            "tick": sim.ticks,
            "turtles": turtles,
            "strokes": strokes,
        }

    def room_scene(self, room: str) -> Scene | None:
        """What ``room``'s robot and billboards are now; None for a room with no robot yet."""
        robot = self.rooms.get(room)
        return None if robot is None else robot.sim.scene()

    def tick(self) -> None:
        """One step of every robot, then a word to every writer that new messages are there."""
        now = time.monotonic()
        if self.turtle is not None:
            self.turtle.step(now)
        for robot in self.rooms.values():
            robot.step(now)
        self.ticks += 1
        self.wake()

    def wake(self) -> None:
        """Tell every writer there may be something new to send (a tick, a publication)."""
        for _, outbox in self.outboxes.items():
            outbox.wake()

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

    async def _film(self, robot: RoomRobot) -> None:
        """Render and publish ``robot``'s camera at its frame rate while anyone subscribes."""
        loop = asyncio.get_running_loop()
        thread, renderer = await self._camera()
        period = 1.0 / renderer.camera.fps
        next_at = loop.time()
        while True:
            if robot.hub.camera_wanted():
                scene, stamp = robot.sim.scene(), time.time()
                jpeg = await loop.run_in_executor(thread, _shoot, renderer, scene)
                robot.hub.publish_frame(jpeg, stamp)
                self.wake()
            next_at += period
            delay = next_at - loop.time()
            if delay < -MAX_LAG_S:
                next_at = loop.time()
            await asyncio.sleep(max(delay, 0.0))

    async def _camera(self) -> tuple[ThreadPoolExecutor, Renderer]:
        """The thread every room's camera renders in and the renderer they share, made for the
        first room (a turtlesim server never loads the photos) -- in that thread, so that
        loading them never holds up a tick."""
        if self._camera_thread is None:
            self._camera_thread = ThreadPoolExecutor(1, thread_name_prefix="camera")
            self._renderer = asyncio.get_running_loop().run_in_executor(
                self._camera_thread, _renderer
            )
        assert self._renderer is not None
        return self._camera_thread, await self._renderer


def _renderer() -> Renderer:
    """The camera of the diffdrive robot over its room (in the camera thread)."""
    from app.diffdrive.camera import Pinhole, Renderer

    return Renderer(RoomSim().room, Pinhole(hfov=CAMERA_HFOV))


def _shoot(renderer: Renderer, scene: Scene) -> bytes:
    """One camera frame of ``scene`` as JPEG (in the camera thread)."""
    from app.diffdrive.camera import encode_jpeg

    return encode_jpeg(renderer.render(scene))


def _requested_room(websocket: WebSocket) -> str | None:
    """The room a connection without access control asks for (``?room=R``, else the default);
    None when the name is not a room's."""
    try:
        return _ROOM_NAME.validate_python(websocket.query_params.get("room", DEFAULT_ROOM))
    except ValidationError:
        return None


@router.get("/turtlesim/state")
async def turtlesim_state(request: Request) -> dict[str, Any]:
    """Read-only view of the simulator: poses, pens and pen strokes (a token of any role)."""
    refusal = state_refusal(
        request.app.state.settings.secret, bearer_token(request.headers), time.time()
    )
    if refusal is not None:
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, refusal, {"WWW-Authenticate": "Bearer"})
    simulator: Simulator = request.app.state.simulator
    if simulator.turtle is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"the server simulates {simulator.robot}")
    return simulator.state()


@router.get(STATE_PATH)
async def room_state_view(request: Request) -> dict[str, Any]:
    """Where the billboards of a room stand now, for the client's map: the room its token names
    (a token of any role), or without access control the one ``?room=R`` names."""
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
    if simulator.robot != "diffdrive":
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"the server simulates {simulator.robot}")
    scene = simulator.room_scene(room)
    if scene is None:  # no connection has made the room's robot yet: it stands at its start
        scene = RoomSim().scene()
    converted: dict[str, Any] = to_json(room_state(scene))
    return converted


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
        gate.bind(room if simulator.turtle is None else None)
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
