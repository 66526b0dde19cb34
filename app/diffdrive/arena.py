"""The arena the simulated robot drives in: its walls and the billboards placed in it.

Coordinates are the arena's: metres, origin at the south-west corner on the floor, x east, y
north, heights above the floor; a yaw is counter-clockwise from +x, as turtlesim's theta. A
billboard is a picture on a vertical rectangle: a face photo at head height (with a flat body
below it for a person), or a flame on a stand. Its ``yaw`` is the way its picture faces; seen
from behind it shows a blank back. The walking person is the one billboard that moves: it
follows a closed path and always turns its face to the robot, as a person who keeps an eye on
it would (a picture seen edge-on would vanish).

The face photos are scaled so that the box the face cascade finds on them (measured once, in
``face_box``) is :data:`FACE_BOX_M` high in the arena: the onboard law's range estimate from
the box's height then reads the true distance.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Final, Literal

# The real height of the face box the cascade finds on every face billboard, and the height
# of that box's centre above the floor (an adult's face).
FACE_BOX_M: Final = 0.24
FACE_CENTRE_HEIGHT_M: Final = 1.55
# How much of the photo around the face box is kept, as a share of the box's size on each
# side: hair, ears and chin, so the cascade sees a whole face.
FACE_MARGIN: Final = 0.35


@dataclass(frozen=True)
class Pose2D:
    """A place on the floor and a heading."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class FacePhoto:
    """A face photo in ``app/assets`` and the face box the cascade finds on it.

    ``size`` and ``face_box`` (x, y, w, h) are in the photo's pixels, measured once with
    OpenCV's ``haarcascade_frontalface_default`` (scale 1.1, 5 neighbours) on the full photo;
    the renderer checks the file still has that size.
    """

    file: str
    size: tuple[int, int]
    face_box: tuple[int, int, int, int]

    @property
    def crop(self) -> tuple[int, int, int, int]:
        """The part of the photo shown, (x0, y0, x1, y1): the face box and its margin."""
        x, y, w, h = self.face_box
        width, height = self.size
        return (
            max(0, round(x - FACE_MARGIN * w)),
            max(0, round(y - FACE_MARGIN * h)),
            min(width, round(x + (1 + FACE_MARGIN) * w)),
            min(height, round(y + (1 + FACE_MARGIN) * h)),
        )

    @property
    def metres_per_pixel(self) -> float:
        """The photo's scale in the arena: its face box is :data:`FACE_BOX_M` high."""
        return FACE_BOX_M / self.face_box[3]


OBAMA: Final = FacePhoto("obama.jpg", (910, 1137), (342, 95, 300, 300))
BIDEN: Final = FacePhoto("biden.jpg", (970, 2204), (433, 211, 314, 314))


@dataclass(frozen=True)
class Picture:
    """Where a billboard's picture sits on it: its size and the height of its bottom edge."""

    width: float
    height: float
    bottom: float


@dataclass(frozen=True)
class Face:
    """A face photo at head height; ``body`` (a BGR colour) adds a flat body below it."""

    photo: FacePhoto
    body: tuple[int, int, int] | None = None
    kind: Literal["face"] = "face"

    @cached_property
    def picture(self) -> Picture:
        """The photo's real size and place: the face box's centre at face height."""
        x0, y0, x1, y1 = self.photo.crop
        scale = self.photo.metres_per_pixel
        bx, by, _, bh = self.photo.face_box
        below_centre = (y1 - (by + bh / 2)) * scale
        return Picture((x1 - x0) * scale, (y1 - y0) * scale, FACE_CENTRE_HEIGHT_M - below_centre)

    @property
    def face_centre_height(self) -> float:
        """Height of the face box's centre above the floor."""
        return FACE_CENTRE_HEIGHT_M


@dataclass(frozen=True)
class Flame:
    """A flame ``picture.width`` by ``picture.height``, standing ``picture.bottom`` above the
    floor (on a stand: the camera's lower edge sees the floor only a couple of metres out)."""

    picture: Picture
    kind: Literal["flame"] = "flame"


Look = Face | Flame


@dataclass(frozen=True)
class Leg:
    """One leg of a walk: to ``to`` at ``speed`` m/s, then a ``pause`` there (s)."""

    to: tuple[float, float]
    speed: float
    pause: float = 0.0


@dataclass(frozen=True)
class Walk:
    """A closed walk from ``start`` along ``legs``, the last of them back to the start, over
    and over."""

    start: tuple[float, float]
    legs: tuple[Leg, ...]

    def __post_init__(self) -> None:
        if not self.legs or self.legs[-1].to != self.start:
            raise ValueError("a walk's last leg ends where it started")
        if any(leg.speed <= 0 or leg.pause < 0 for leg in self.legs):
            raise ValueError("a walk's legs need a positive speed and no negative pause")

    @cached_property
    def _timeline(self) -> tuple[tuple[float, ...], tuple[tuple[float, float, float, float], ...]]:
        """Each stretch's start time, and the stretch: (x0, y0, x1, y1) walked at its speed,
        or a pause where x0, y0 == x1, y1."""
        times: list[float] = []
        stretches: list[tuple[float, float, float, float]] = []
        t = 0.0
        x, y = self.start
        for leg in self.legs:
            tx, ty = leg.to
            times.append(t)
            stretches.append((x, y, tx, ty))
            t += math.hypot(tx - x, ty - y) / leg.speed
            if leg.pause > 0:
                times.append(t)
                stretches.append((tx, ty, tx, ty))
                t += leg.pause
            x, y = tx, ty
        times.append(t)
        return tuple(times), tuple(stretches)

    @property
    def period_s(self) -> float:
        """How long one round takes."""
        return self._timeline[0][-1]

    def at(self, t: float) -> tuple[float, float]:
        """Where the walker is ``t`` seconds after it set off from ``start``."""
        times, stretches = self._timeline
        phase = t % times[-1]
        i = bisect.bisect_right(times, phase) - 1
        x0, y0, x1, y1 = stretches[i]
        span = times[i + 1] - times[i]
        u = 0.0 if span <= 0 else (phase - times[i]) / span
        return x0 + (x1 - x0) * u, y0 + (y1 - y0) * u


@dataclass(frozen=True)
class Billboard:
    """A picture in the arena: at ``pose``, or walking ``walk`` (then it faces the robot)."""

    name: str
    look: Look
    pose: Pose2D | None = None
    walk: Walk | None = None

    def __post_init__(self) -> None:
        if (self.pose is None) == (self.walk is None):
            raise ValueError(f"billboard {self.name!r} needs a pose or a walk, not both")

    def placed(self, t: float, robot: tuple[float, float]) -> Pose2D:
        """Where it stands at arena time ``t`` and which way it faces, the robot at ``robot``."""
        if self.pose is not None:
            return self.pose
        assert self.walk is not None
        x, y = self.walk.at(t)
        return Pose2D(x, y, math.atan2(robot[1] - y, robot[0] - x))


@dataclass(frozen=True)
class Arena:
    """A rectangular arena ``width`` (x) by ``depth`` (y) with walls ``wall_height`` high, the
    billboards in it, and where the robot starts."""

    width: float
    depth: float
    wall_height: float
    start: Pose2D
    billboards: tuple[Billboard, ...]

    def billboard(self, name: str) -> Billboard:
        """The billboard called ``name``; ``KeyError`` when there is none."""
        for billboard in self.billboards:
            if billboard.name == name:
                return billboard
        raise KeyError(f"no billboard named {name!r}")


def facing(at: tuple[float, float], towards: tuple[float, float]) -> float:
    """The yaw of something at ``at`` that faces ``towards``."""
    return math.atan2(towards[1] - at[1], towards[0] - at[0])


START: Final = Pose2D(1.0, 3.0, 0.0)

# The walking person: off ahead of the robot, east along the middle of the arena, a pause,
# then back west at a jog along a line 0.6 m to the north -- past the side of a robot that has
# followed it, to behind it -- another pause, and round the south half back to the start.
# Passing 0.6 m from the robot at 1.6 m/s, its bearing turns at up to 2.7 rad/s: faster than a
# law that steers in proportion to the bearing keeps it in a 60° view, so the law must search.
WALK: Final = Walk(
    start=(2.5, 3.0),
    legs=(
        Leg((6.0, 3.0), speed=0.6, pause=2.0),
        Leg((6.0, 3.6), speed=0.8),
        Leg((1.5, 3.6), speed=1.6, pause=3.0),
        Leg((1.5, 1.6), speed=0.6),
        Leg((4.5, 1.5), speed=0.6, pause=2.0),
        Leg((2.5, 3.0), speed=0.6),
    ),
)

BYSTANDER_AT: Final = (3.4, 1.9)
FLAME_AT: Final = (7.7, 1.2)

ARENA: Final = Arena(
    width=8.0,
    depth=6.0,
    wall_height=2.5,
    start=START,
    billboards=(
        Billboard("walker", Face(OBAMA, body=(70, 60, 50)), walk=WALK),
        # The second face, for the target lock: a person standing still, facing the start.
        Billboard(
            "bystander",
            Face(BIDEN, body=(110, 80, 60)),
            pose=Pose2D(*BYSTANDER_AT, facing(BYSTANDER_AT, (START.x, START.y))),
        ),
        # The demo's flame, on a stand by the east wall, facing west.
        Billboard("flame", Flame(Picture(0.35, 0.5, 0.6)), pose=Pose2D(*FLAME_AT, math.pi)),
    ),
)
