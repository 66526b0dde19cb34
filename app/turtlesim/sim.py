"""A turtlesim that behaves like ROS ``turtlesim_node``, as plain synchronous code.

No sockets, no asyncio: the owner calls :meth:`TurtleSim.step` once per tick and the clock used
for the one-second command timeout is injected, so tests drive time themselves.

Coordinates are turtlesim's: metres, origin at the bottom-left corner of the square world, y up,
theta in radians counter-clockwise from +x, kept in [-pi, pi) after every tick.

One tick does what turtlesim's per-turtle update does, in its order (the facts are recorded in
``docs/turtlesim-facts.md``): the teleports queued since the last tick, in order and unclamped;
the one-second command timeout; the turn; the move along the new heading (holonomic: ``linear_y``
moves sideways); the clamp to the world. A spawned turtle is placed as asked and clamped by its
first tick too. Service arguments are float32 in turtlesim's interfaces and rounded to float32
here as they are there.
"""

from __future__ import annotations

import math
import re
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

# turtlesim's own turtle-name rule is ROS's graph-name rule; names also become topic prefixes.
_NAME_RE = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
# Beyond this many points per turtle the oldest are dropped, so hours of driving stay bounded.
MAX_TRAIL_POINTS = 20_000
# A point is added to the trail only when the turtle has moved at least this far (m):
# turning in place adds nothing.
_TRAIL_MIN_STEP_M = 1e-3


@dataclass
class Pose:
    """A turtle's pose, as in ``turtlesim/Pose``."""

    x: float
    y: float
    theta: float
    linear_velocity: float
    angular_velocity: float


@dataclass(frozen=True)
class Pen:
    """A turtle's pen, as set by ``set_pen`` (turtlesim's default colour and width)."""

    r: int = 179
    g: int = 184
    b: int = 255
    width: int = 3
    off: bool = False


@dataclass
class Stroke:
    """One continuous line drawn by one turtle with one pen."""

    turtle: str
    pen: Pen
    points: list[tuple[float, float]] = field(default_factory=list)


@dataclass(frozen=True)
class _Teleport:
    """A queued ``teleport_absolute`` (x, y, theta) or ``teleport_relative`` (linear, theta)."""

    relative: bool
    theta: float
    x: float = 0.0
    y: float = 0.0
    linear: float = 0.0


@dataclass
class _Turtle:
    x: float
    y: float
    theta: float
    # turtlesim starts the timeout clock when the turtle is made.
    last_command: float
    linear_x: float = 0.0
    linear_y: float = 0.0
    angular_z: float = 0.0
    pen: Pen = field(default_factory=Pen)
    # The stroke this turtle is drawing, None while the pen is off or after ``clear``.
    stroke: Stroke | None = None
    teleports: list[_Teleport] = field(default_factory=list)


def normalize_angle(angle: float) -> float:
    """Wrap an angle into [-pi, pi), as turtlesim does."""
    return angle - 2.0 * math.pi * math.floor((angle + math.pi) / (2.0 * math.pi))


def float32(value: float) -> float:
    """``value`` rounded to the nearest float32, as a float32 field of a ROS interface holds it."""
    result: float = struct.unpack("f", struct.pack("f", value))[0]
    return result


class TurtleSim:
    """The turtlesim world: turtles, their commands, and the pen strokes they leave."""

    # turtlesim's canvas is 500 px with a 45 px turtle image as one metre; the last pixel row is
    # the far edge, hence (500 - 1) / 45, held in a float32 as turtlesim holds it.
    WORLD_SIZE = float32((500 - 1) / 45)
    TICK_S = 0.016
    COMMAND_TIMEOUT_S = 1.0
    CENTRE = WORLD_SIZE / 2.0
    # Qt's default pen width, which turtlesim keeps when set_pen asks for width 0.
    DEFAULT_PEN_WIDTH = 1

    def __init__(self, clock: Callable[[], float] = time.monotonic, holonomic: bool = True) -> None:
        self._clock = clock
        # Whether cmd_vel's linear.y moves the turtle sideways: always in noetic and humble; in
        # the turtlesim_msgs era only with the node parameter ``holonomic``.
        self.holonomic = holonomic
        self._turtles: dict[str, _Turtle] = {}
        self._strokes: list[Stroke] = []
        # Points drawn per turtle name, so trimming is only computed when a trail is too long.
        self._trail_points: dict[str, int] = {}
        self._id_counter = 0
        self.ticks = 0
        self.spawn(self.CENTRE, self.CENTRE, 0.0)

    # -- time ------------------------------------------------------------------------------

    def step(self) -> None:
        """Advance one fixed 16 ms tick, whatever the wall time since the last one."""
        now = self._clock()
        dt = self.TICK_S
        for turtle in self._turtles.values():
            for teleport in turtle.teleports:
                self._apply(turtle, teleport)
            turtle.teleports.clear()
            if now - turtle.last_command > self.COMMAND_TIMEOUT_S:
                turtle.linear_x = turtle.linear_y = turtle.angular_z = 0.0
            turtle.theta = normalize_angle(turtle.theta + turtle.angular_z * dt)
            cos, sin = math.cos(turtle.theta), math.sin(turtle.theta)
            turtle.x += (cos * turtle.linear_x - sin * turtle.linear_y) * dt
            turtle.y += (sin * turtle.linear_x + cos * turtle.linear_y) * dt
            turtle.x, turtle.y = self._clamp(turtle.x), self._clamp(turtle.y)
            self._draw_to(turtle)
        self.ticks += 1

    # -- commands --------------------------------------------------------------------------

    def cmd_vel(self, name: str, linear_x: float, angular_z: float, linear_y: float = 0.0) -> None:
        """Set a turtle's velocities until the next command or for one second, whichever first.

        ``linear_y`` (sideways, m/s) is taken only while :attr:`holonomic` is set; otherwise the
        sideways velocity keeps its value, as turtlesim leaves it alone.
        """
        turtle = self._turtle(name)
        turtle.linear_x = float(linear_x)
        if self.holonomic:
            turtle.linear_y = float(linear_y)
        turtle.angular_z = float(angular_z)
        turtle.last_command = self._clock()

    def pose(self, name: str) -> Pose:
        """The turtle's pose as its last tick left it (a turtle spawned since then: as asked).

        ``linear_velocity`` is the speed, sqrt(vx^2 + vy^2), as turtlesim publishes it.
        """
        t = self._turtle(name)
        return Pose(t.x, t.y, t.theta, math.hypot(t.linear_x, t.linear_y), t.angular_z)

    def names(self) -> list[str]:
        """Names of the living turtles, in spawn order."""
        return list(self._turtles)

    def pen(self, name: str) -> Pen:
        """The turtle's current pen."""
        return self._turtle(name).pen

    def strokes(self) -> list[Stroke]:
        """Everything drawn since the last ``clear``/``reset``, oldest first."""
        return list(self._strokes)

    # -- services --------------------------------------------------------------------------

    def spawn(self, x: float, y: float, theta: float, name: str = "") -> str:
        """Add a turtle; an empty name becomes ``turtleN``. Returns the name used.

        Raises ``ValueError`` for a name already in use or one that cannot be a topic prefix.
        """
        if not name:
            while True:
                self._id_counter += 1
                name = f"turtle{self._id_counter}"
                if name not in self._turtles:
                    break
        elif name in self._turtles:
            raise ValueError(f"a turtle named {name!r} already exists")
        elif not _NAME_RE.match(name):
            raise ValueError(f"invalid turtle name {name!r}")
        # Placed as asked (float32), clamped and normalised by its first tick, as in turtlesim.
        turtle = _Turtle(
            x=float32(x),
            y=float32(y),
            theta=float32(theta),
            last_command=self._clock(),
        )
        self._turtles[name] = turtle
        self._start_stroke(name, turtle)
        return name

    def kill(self, name: str) -> None:
        """Remove a turtle; what it drew stays on the canvas, as in turtlesim."""
        self._turtle(name)
        del self._turtles[name]

    def reset(self) -> None:
        """Back to the start: the canvas cleared and one ``turtle1`` at the centre."""
        self._turtles.clear()
        self._strokes.clear()
        self._trail_points.clear()
        self._id_counter = 0
        self.spawn(self.CENTRE, self.CENTRE, 0.0)

    def clear(self) -> None:
        """Erase the canvas; turtles stay where they are and keep drawing from there."""
        self._strokes.clear()
        self._trail_points.clear()
        for name, turtle in self._turtles.items():
            self._start_stroke(name, turtle)

    def teleport_absolute(self, name: str, x: float, y: float, theta: float) -> None:
        """Queue a jump to (x, y) facing theta; it happens, and is clamped, on the next tick."""
        self._turtle(name).teleports.append(
            _Teleport(relative=False, x=float32(x), y=float32(y), theta=float32(theta))
        )

    def teleport_relative(self, name: str, linear: float, angular: float) -> None:
        """Queue a turn by ``angular`` then a move of ``linear`` metres along the new heading;
        it happens, and is clamped, on the next tick."""
        self._turtle(name).teleports.append(
            _Teleport(relative=True, linear=float32(linear), theta=float32(angular))
        )

    def set_pen(self, name: str, r: int, g: int, b: int, width: int, off: bool | int) -> None:
        """Change a turtle's pen; colour and width are 0..255 as in turtlesim's uint8 fields.

        ``off`` lifts the pen and leaves its colour and width as they were; width 0 means Qt's
        default width.
        """
        turtle = self._turtle(name)
        for label, value in (("r", r), ("g", g), ("b", b), ("width", width)):
            if not 0 <= value <= 255:
                raise ValueError(f"{label} must be in 0..255, got {value}")
        if off:
            turtle.pen = replace(turtle.pen, off=True)
        else:
            turtle.pen = Pen(r, g, b, width or self.DEFAULT_PEN_WIDTH, False)
        self._start_stroke(name, turtle)

    # -- internals -------------------------------------------------------------------------

    def _turtle(self, name: str) -> _Turtle:
        try:
            return self._turtles[name]
        except KeyError:
            raise KeyError(f"no turtle named {name!r}") from None

    def _clamp(self, value: float) -> float:
        return min(max(float(value), 0.0), self.WORLD_SIZE)

    def _apply(self, turtle: _Turtle, teleport: _Teleport) -> None:
        # No clamp here: a teleport may leave the world until the tick's clamp brings it back.
        if teleport.relative:
            turtle.theta += teleport.theta
            turtle.x += math.cos(turtle.theta) * teleport.linear
            turtle.y += math.sin(turtle.theta) * teleport.linear
        else:
            # Only the top edge is enforced at once (turtlesim's canvas y cannot go below 0).
            turtle.x, turtle.y = teleport.x, min(teleport.y, self.WORLD_SIZE)
            turtle.theta = teleport.theta
        self._draw_to(turtle)

    def _draw_to(self, turtle: _Turtle) -> None:
        stroke = turtle.stroke
        if stroke is None:
            return
        last_x, last_y = stroke.points[-1]
        if math.hypot(turtle.x - last_x, turtle.y - last_y) >= _TRAIL_MIN_STEP_M:
            stroke.points.append((turtle.x, turtle.y))
            self._trail_points[stroke.turtle] = self._trail_points.get(stroke.turtle, 0) + 1
            if self._trail_points[stroke.turtle] > MAX_TRAIL_POINTS:
                self._trim(stroke.turtle)

    def _start_stroke(self, name: str, turtle: _Turtle) -> None:
        if turtle.pen.off:
            turtle.stroke = None
            return
        turtle.stroke = Stroke(turtle=name, pen=turtle.pen, points=[(turtle.x, turtle.y)])
        self._strokes.append(turtle.stroke)
        self._trail_points[name] = self._trail_points.get(name, 0) + 1

    def _trim(self, name: str) -> None:
        own = [s for s in self._strokes if s.turtle == name]
        excess = sum(len(s.points) for s in own) - MAX_TRAIL_POINTS
        for stroke in own:
            if excess <= 0:
                break
            drop = min(excess, len(stroke.points) - 1 if stroke is own[-1] else len(stroke.points))
            del stroke.points[:drop]
            excess -= drop
        self._strokes = [s for s in self._strokes if s.points]
        self._trail_points[name] = sum(len(s.points) for s in own)
