"""The diffdrive robot as the server simulates it (:mod:`app.rosbridge.simulated`): one robot in
its arena for each signaling room, its camera filmed while anyone subscribes, its state for the
map the billboards' places (``GET /arena/state``).

Every room's camera renders through one :class:`~app.diffdrive.camera.Renderer` (:class:`Film`),
loaded when the first is filmed (a server nobody films never loads the photos), in the server's
camera thread: the one thread that renders, so the renderer is never used by two at once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

from app.diffdrive.arena import ARENA
from app.diffdrive.arenamap import STATE_PATH, arena_map, arena_state
from app.diffdrive.robot import CAMERA_HFOV, DiffDrive
from app.diffdrive.rosbridge import DiffDriveHub
from app.diffdrive.sim import ArenaSim, Scene
from app.protocol.page import ArenaMap, to_json
from app.protocol.ros import RosFlavour
from app.protocol.video import VIDEO_FPS

if TYPE_CHECKING:
    from app.diffdrive.camera import Renderer


class Film:
    """The renderer that every room's camera shares, loaded at its first use."""

    def __init__(self) -> None:
        self._renderer: Renderer | None = None

    def load(self) -> Renderer:
        """The renderer, loaded at the first call (in the camera thread)."""
        if self._renderer is None:
            from app.diffdrive.camera import Pinhole, Renderer

            self._renderer = Renderer(ARENA, Pinhole(hfov=CAMERA_HFOV))
        return self._renderer

    def shoot(self, scene: Scene) -> bytes:
        """One camera frame of ``scene`` as JPEG (in the camera thread)."""
        from app.diffdrive.camera import encode_jpeg

        return encode_jpeg(self.load().render(scene))


class ArenaCamera:
    """The robot's onboard camera."""

    fps: Final = VIDEO_FPS

    def __init__(self, sim: ArenaSim, hub: DiffDriveHub, film: Film) -> None:
        self._sim = sim
        self._hub = hub
        self._film = film

    def wanted(self) -> bool:
        """Whether anyone subscribes to the camera topic."""
        return self._hub.camera_wanted()

    def prepare(self) -> None:
        """Load the renderer (the photos) unless another room's camera has."""
        self._film.load()

    def shot(self) -> Callable[[], bytes]:
        """The arena as of now, to render: the scene is taken here, so no later tick moves it."""
        scene = self._sim.scene()
        return lambda: self._film.shoot(scene)

    def publish(self, jpeg: bytes, stamp_s: float) -> None:
        """The frame goes out on the camera topic."""
        self._hub.publish_frame(jpeg, stamp_s)


class ArenaRobot:
    """One room's differential-drive robot in its arena, its hub, and its camera."""

    def __init__(self, ros: RosFlavour, film: Film) -> None:
        self.sim = ArenaSim()
        self.hub = DiffDriveHub(self.sim, ros)
        self.camera = ArenaCamera(self.sim, self.hub, film)

    def step(self, now: float) -> None:
        """One tick of the arena, then of its hub."""
        self.sim.step()
        self.hub.tick(now)

    def state(self) -> dict[str, Any]:
        """Where the billboards stand now, and the arena's time."""
        converted: dict[str, Any] = to_json(arena_state(self.sim.scene()))
        return converted


class DiffDriveSimulation:
    """The diffdrive robot: one per signaling room, each in its own arena, their cameras drawn
    by one renderer."""

    per_room: Final = True
    tick_s: Final = DiffDrive.TICK_S
    state_path: Final = STATE_PATH

    def __init__(self) -> None:
        self._film = Film()

    def robot(self, ros: RosFlavour) -> ArenaRobot:
        """A robot at the arena's start."""
        return ArenaRobot(ros, self._film)

    def arena_map(self) -> ArenaMap:
        """The arena's layout and the camera's field of view, for the client's map."""
        return arena_map(ARENA, CAMERA_HFOV)
