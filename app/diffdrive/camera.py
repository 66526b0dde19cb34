"""The robot's onboard camera: a pinhole looking along the robot's heading, and a renderer.

:class:`Pinhole` is the geometry: a point of the arena seen from the robot's pose lands at pixel
``u = cx - f * left / ahead``, ``v = cy - f * up / ahead``, with ``f = (w / 2) / tan(hfov / 2)``
and pixel coordinates continuous (the first pixel spans 0 to 1, the image centre is w / 2).
So a target's bearing, positive to the left as the robot's yaw is, is ``atan((cx - u) / f)``.

:class:`Renderer` draws what the camera sees of a :class:`~app.diffdrive.sim.Scene`: the floor
and ceiling shaded by distance, the four walls by ray casting one ray per pixel column (shaded
by distance, a seam every metre so that turning shows), then each billboard from the farthest
to the nearest -- its four corners projected, the part behind the camera cut off, its picture
warped into place with ``cv2.warpPerspective`` on just the pixels it covers. Images are BGR, as
OpenCV's JPEG encoder takes them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import cv2
import numpy as np
import numpy.typing as npt

from app.diffdrive.arena import Arena, Face, Flame, Picture, Pose2D
from app.diffdrive.robot import CAMERA_HEIGHT_M, CAMERA_HFOV, RobotState
from app.diffdrive.sim import Placed, Scene
from app.flame import draw_flame_bgr
from app.protocol.video import VIDEO_FPS, VIDEO_SIZE
from app.resources import FACES_DIR

Image = npt.NDArray[np.uint8]
Floats = npt.NDArray[np.float64]

# What lies nearer the camera than this (m) is not drawn: the clipping plane's distance.
NEAR_M: Final = 0.05
# JPEG quality of the published frames.
JPEG_QUALITY: Final = 80

# Pixels high of the largest copy of each face's box kept for warping: more than a face at a
# metre covers in a 640x480 frame; smaller copies (halving) serve faces farther away, so that
# warping never skips over texels (which would alias the face the cascade is to find).
FACE_TEXTURE_PX: Final = 160
FLAME_TEXTURE_PX: Final = 200
# Flame pictures drawn ahead, played in turn (it flickers at the camera's frame rate).
FLAME_FRAMES: Final = 32

# Colours (BGR) and shading.
_WALLS: Final = {  # by the side of the arena the wall is on
    "south": (170, 190, 205),
    "east": (150, 175, 200),
    "north": (185, 200, 210),
    "west": (160, 170, 185),
}
_FLOOR: Final = (80, 105, 130)
_CEILING: Final = (225, 228, 230)
_BACK: Final = (120, 125, 130)  # a billboard's blank back
_SEAM_M: Final = 0.04  # how wide the seams between wall panels are
_SEAM_SHADE: Final = 0.7
# A person's body, under the photo, is this share of the photo's width.
_BODY_WIDTH: Final = 0.75


def _shade(depth: Floats) -> Floats:
    """Brightness by distance: near things are lit, far ones dim (never black)."""
    return np.clip(1.05 - 0.08 * depth, 0.35, 1.0)


@dataclass(frozen=True)
class Pinhole:
    """A level pinhole camera at the robot's centre, ``mount_height`` above the floor."""

    width: int = VIDEO_SIZE[0]
    height: int = VIDEO_SIZE[1]
    hfov: float = CAMERA_HFOV
    mount_height: float = CAMERA_HEIGHT_M
    fps: float = VIDEO_FPS

    def __post_init__(self) -> None:
        if not 0 < self.hfov < math.pi:
            raise ValueError(f"a pinhole's field of view is between 0 and 180°, not {self.hfov}")

    @property
    def focal(self) -> float:
        """Focal length in pixels."""
        return (self.width / 2) / math.tan(self.hfov / 2)

    @property
    def centre(self) -> tuple[float, float]:
        """The principal point (the image centre)."""
        return self.width / 2, self.height / 2

    def to_camera(self, robot: RobotState, x: float, y: float, z: float) -> tuple[float, ...]:
        """An arena point as (ahead, left, up) metres from the camera."""
        dx, dy = x - robot.x, y - robot.y
        cos, sin = math.cos(robot.yaw), math.sin(robot.yaw)
        return dx * cos + dy * sin, -dx * sin + dy * cos, z - self.mount_height

    def project(
        self, robot: RobotState, x: float, y: float, z: float
    ) -> tuple[float, float] | None:
        """The pixel (u, v) where the arena point (x, y, z) appears; None when it is behind the
        camera (or in the clipping plane's way). It may lie outside the frame."""
        ahead, left, up = self.to_camera(robot, x, y, z)
        if ahead < NEAR_M:
            return None
        cx, cy = self.centre
        return cx - self.focal * left / ahead, cy - self.focal * up / ahead

    def bearing(self, robot: RobotState, x: float, y: float) -> float:
        """The bearing of the arena point (x, y) from the robot's heading, positive to the
        left, in (-π, π]."""
        ahead, left, _ = self.to_camera(robot, x, y, self.mount_height)
        return math.atan2(left, ahead)

    def pixel_bearing(self, u: float) -> float:
        """The bearing of pixel column ``u``, positive to the left."""
        return math.atan((self.centre[0] - u) / self.focal)


# -- textures ------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Texture:
    """A billboard's picture at several sizes (largest first) and the mask of what is drawn
    (None: all of it)."""

    levels: tuple[Image, ...]
    masks: tuple[Image, ...] | None = None

    def level_for(self, pixels_high: float) -> int:
        """The smallest copy at least ``pixels_high`` high (the largest when none is)."""
        best = 0
        for i, image in enumerate(self.levels):
            if image.shape[0] >= pixels_high:
                best = i
        return best


def _pyramid(image: Image, smallest: int = 16) -> tuple[Image, ...]:
    levels = [image]
    while min(levels[-1].shape[:2]) >= 2 * smallest:
        last = levels[-1]
        size = (max(1, last.shape[1] // 2), max(1, last.shape[0] // 2))
        levels.append(np.asarray(cv2.resize(last, size, interpolation=cv2.INTER_AREA)))
    return tuple(levels)


def load_face(face: Face, faces_dir: Path = FACES_DIR) -> tuple[Image, ...]:
    """The face's photo, cropped to its face box and margin, at sizes from the face box
    :data:`FACE_TEXTURE_PX` high down; ``ValueError`` when the file is missing or is not the
    photo the arena was measured on."""
    path = faces_dir / face.photo.file
    loaded = cv2.imread(str(path))
    if loaded is None:
        raise ValueError(f"cannot read face photo {path}")
    photo: Image = np.asarray(loaded, dtype=np.uint8)
    if (photo.shape[1], photo.shape[0]) != face.photo.size:
        raise ValueError(
            f"{path} is {photo.shape[1]}x{photo.shape[0]}, not the "
            f"{face.photo.size[0]}x{face.photo.size[1]} photo whose face box the arena knows"
        )
    x0, y0, x1, y1 = face.photo.crop
    scale = FACE_TEXTURE_PX / face.photo.face_box[3]
    size = (round((x1 - x0) * scale), round((y1 - y0) * scale))
    crop = cv2.resize(photo[y0:y1, x0:x1], size, interpolation=cv2.INTER_AREA)
    return _pyramid(np.asarray(crop, dtype=np.uint8))


def flame_frames(flame: Flame, frames: int = FLAME_FRAMES) -> tuple[list[Image], list[Image]]:
    """The flame picture (BGR on black) and its mask, for each of ``frames`` flickers."""
    height = FLAME_TEXTURE_PX
    width = round(height * flame.picture.width / flame.picture.height)
    pictures: list[Image] = []
    masks: list[Image] = []
    for i in range(frames):
        picture: Image = np.zeros((height, width, 3), np.uint8)
        # The flame is about 0.8 of its full height: it stands inside the picture.
        draw_flame_bgr(picture, width / 2, height * 0.55, i, full=height * 0.8)
        pictures.append(picture)
        masks.append(np.where(picture.any(axis=2), 255, 0).astype(np.uint8))
    return pictures, masks


@dataclass(frozen=True)
class VisiblePart:
    """The part of a picture in front of the camera: from ``start`` to ``end`` across it (0 is
    its left edge as seen from the front, 1 its right edge), and the pixels of that part's
    corners -- top left, top right, bottom right, bottom left (4×2, maybe outside the frame)."""

    start: float
    end: float
    corners: Floats


def visible_part(
    camera: Pinhole, robot: RobotState, pose: Pose2D, picture: Picture
) -> VisiblePart | None:
    """What of ``picture`` at ``pose`` lies ahead of the camera's clipping plane, cut along the
    plane (a picture is upright and the plane too, so the cut is a vertical line across it);
    None when none of it does."""
    # The picture's left and right edges as a viewer in front of it sees them.
    rx, ry = -math.sin(pose.yaw), math.cos(pose.yaw)
    half = picture.width / 2
    ends = [(pose.x - half * rx, pose.y - half * ry), (pose.x + half * rx, pose.y + half * ry)]
    ahead = [camera.to_camera(robot, x, y, 0.0)[0] for x, y in ends]
    start, end = 0.0, 1.0
    if ahead[0] < NEAR_M and ahead[1] < NEAR_M:
        return None
    if ahead[0] < NEAR_M:
        start = (NEAR_M - ahead[0]) / (ahead[1] - ahead[0])
    elif ahead[1] < NEAR_M:
        end = (NEAR_M - ahead[0]) / (ahead[1] - ahead[0])
    top, bottom = picture.bottom + picture.height, picture.bottom
    corners = []
    cx, cy = camera.centre
    for s, z in ((start, top), (end, top), (end, bottom), (start, bottom)):
        x = ends[0][0] + s * (ends[1][0] - ends[0][0])
        y = ends[0][1] + s * (ends[1][1] - ends[0][1])
        a, left, up = camera.to_camera(robot, x, y, z)
        a = max(a, NEAR_M)  # a cut corner is on the plane, give or take a rounding
        corners.append((cx - camera.focal * left / a, cy - camera.focal * up / a))
    return VisiblePart(start, end, np.array(corners, np.float64))


# -- the renderer --------------------------------------------------------------------------


class Renderer:
    """Draws what ``camera`` sees of scenes in ``arena``; the textures are loaded once."""

    def __init__(self, arena: Arena, camera: Pinhole, faces_dir: Path = FACES_DIR) -> None:
        self.arena = arena
        self.camera = camera
        self._faces: dict[str, _Texture] = {}
        self._flames: dict[str, list[_Texture]] = {}
        for billboard in arena.billboards:
            look = billboard.look
            if isinstance(look, Face):
                self._faces[billboard.name] = _Texture(load_face(look, faces_dir))
            else:
                pictures, masks = flame_frames(look)
                self._flames[billboard.name] = [
                    _Texture((p,), (m,)) for p, m in zip(pictures, masks, strict=True)
                ]
        cx, cy = camera.centre
        # Each pixel column's ray, as its leftward slope: the ray is ahead + slope * left.
        columns = np.arange(camera.width, dtype=np.float64) + 0.5
        self._slopes: Floats = (cx - columns) / camera.focal
        self._rows: Floats = (np.arange(camera.height, dtype=np.float64) + 0.5)[:, None]
        self._background = self._floor_and_ceiling()

    # -- the whole frame ---------------------------------------------------------------

    def render(self, scene: Scene) -> Image:
        """The camera's view of ``scene``, an H×W×3 BGR image."""
        frame = self._background.copy()
        self._draw_walls(frame, scene.robot)
        robot = scene.robot
        ordered = sorted(
            scene.billboards,
            key=lambda p: -math.hypot(p.pose.x - robot.x, p.pose.y - robot.y),
        )
        for placed in ordered:
            self._draw_billboard(frame, robot, placed, scene.t)
        return frame

    # -- floor, ceiling and walls ------------------------------------------------------

    def _floor_and_ceiling(self) -> Image:
        cam = self.camera
        cy, f = cam.centre[1], cam.focal
        below = self._rows[:, 0] - cy  # > 0 under the horizon
        with np.errstate(divide="ignore"):
            floor_depth = np.where(below > 0, f * cam.mount_height / below, np.inf)
            ceiling_depth = np.where(
                below < 0, f * (self.arena.wall_height - cam.mount_height) / -below, np.inf
            )
        floor = _shade(floor_depth)[:, None] * np.array(_FLOOR, np.float64)
        ceiling = _shade(ceiling_depth)[:, None] * np.array(_CEILING, np.float64)
        rows = np.where((below > 0)[:, None], floor, ceiling)
        return np.repeat(rows[:, None, :], cam.width, axis=1).round().astype(np.uint8)

    def _draw_walls(self, frame: Image, robot: RobotState) -> None:
        cam, arena = self.camera, self.arena
        cos, sin = math.cos(robot.yaw), math.sin(robot.yaw)
        # Ray per column: ahead (cos, sin) plus slope times left (-sin, cos); its parameter is
        # the depth along the optical axis.
        dx = cos - self._slopes * sin
        dy = sin + self._slopes * cos
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(
                dx > 0, (arena.width - robot.x) / dx, np.where(dx < 0, -robot.x / dx, np.inf)
            )
            ty = np.where(
                dy > 0, (arena.depth - robot.y) / dy, np.where(dy < 0, -robot.y / dy, np.inf)
            )
        on_x = tx < ty  # the ray meets an east or west wall first
        depth = np.maximum(np.minimum(tx, ty), NEAR_M)
        along = np.where(on_x, robot.y + tx * dy, robot.x + ty * dx)
        colours = self._wall_colours(on_x, dx, dy)
        seam = np.abs(along - np.round(along)) < _SEAM_M / 2
        colours = colours * (_shade(depth) * np.where(seam, _SEAM_SHADE, 1.0))[:, None]
        cy, f = cam.centre[1], cam.focal
        top = cy - f * (arena.wall_height - cam.mount_height) / depth
        bottom = cy + f * cam.mount_height / depth
        mask = ((self._rows >= top) & (self._rows < bottom)).view(np.uint8)
        walls = np.broadcast_to(colours.round().astype(np.uint8)[None, :, :], frame.shape)
        # OpenCV's masked copy: numpy's (copyto with where=) takes several times as long.
        cv2.copyTo(np.ascontiguousarray(walls), mask, frame)

    @staticmethod
    def _wall_colours(on_x: npt.NDArray[np.bool_], dx: Floats, dy: Floats) -> Floats:
        side = np.where(on_x, np.where(dx > 0, 1, 3), np.where(dy > 0, 2, 0))
        table = np.array([_WALLS[s] for s in ("south", "east", "north", "west")], np.float64)
        colours: Floats = table[side]
        return colours

    # -- billboards --------------------------------------------------------------------

    def _draw_billboard(self, frame: Image, robot: RobotState, placed: Placed, t: float) -> None:
        look, pose = placed.billboard.look, placed.pose
        picture = look.picture
        cam = self.camera
        facing_us = (robot.x - pose.x) * math.cos(pose.yaw) + (robot.y - pose.y) * math.sin(
            pose.yaw
        ) > 0
        if isinstance(look, Face) and look.body is not None:
            body = Picture(picture.width * _BODY_WIDTH, picture.bottom, 0.0)
            self._fill(frame, robot, pose, body, look.body)
        if not facing_us:
            self._fill(frame, robot, pose, picture, _BACK)
            return
        if isinstance(look, Face):
            self._warp(frame, robot, pose, picture, self._faces[placed.billboard.name])
        else:
            flames = self._flames[placed.billboard.name]
            self._warp(frame, robot, pose, picture, flames[round(t * cam.fps) % len(flames)])

    def _region(self, corners: Floats) -> tuple[int, int, int, int] | None:
        """The frame's pixels the corners' bounding box covers, (x0, y0, x1, y1), or None."""
        cam = self.camera
        x0 = max(0, math.floor(corners[:, 0].min()))
        y0 = max(0, math.floor(corners[:, 1].min()))
        x1 = min(cam.width, math.ceil(corners[:, 0].max()))
        y1 = min(cam.height, math.ceil(corners[:, 1].max()))
        return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None

    def _fill(
        self,
        frame: Image,
        robot: RobotState,
        pose: Pose2D,
        picture: Picture,
        colour: tuple[int, int, int],
    ) -> None:
        quad = visible_part(self.camera, robot, pose, picture)
        if quad is None or self._region(quad.corners) is None:
            return
        # fillConvexPoly takes fixed-point pixel centres: shift by half a pixel, 4 bits.
        points = np.round((quad.corners - 0.5) * 16).astype(np.int32)
        cv2.fillConvexPoly(frame, points, colour, lineType=cv2.LINE_8, shift=4)

    def _warp(
        self, frame: Image, robot: RobotState, pose: Pose2D, picture: Picture, texture: _Texture
    ) -> None:
        quad = visible_part(self.camera, robot, pose, picture)
        if quad is None:
            return
        s0, s1, corners = quad.start, quad.end, quad.corners
        region = self._region(corners)
        if region is None:
            return
        x0, y0, x1, y1 = region
        level = texture.level_for(corners[:, 1].max() - corners[:, 1].min())
        image = texture.levels[level]
        th, tw = image.shape[:2]
        source = np.array(
            [(s0 * tw, 0.0), (s1 * tw, 0.0), (s1 * tw, th), (s0 * tw, th)], np.float32
        )
        # Both sides' corners in OpenCV's convention (pixel centres at whole numbers), the
        # target's relative to the region drawn.
        target = (corners - (x0 + 0.5, y0 + 0.5)).astype(np.float32)
        matrix = cv2.getPerspectiveTransform(source - 0.5, target)
        size = (x1 - x0, y1 - y0)
        region_pixels = np.ascontiguousarray(frame[y0:y1, x0:x1])
        if texture.masks is None:
            cv2.warpPerspective(
                image,
                matrix,
                size,
                dst=region_pixels,
                flags=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_TRANSPARENT,
            )
        else:
            warped = cv2.warpPerspective(image, matrix, size, flags=cv2.INTER_LINEAR)
            mask = cv2.warpPerspective(texture.masks[level], matrix, size, flags=cv2.INTER_NEAREST)
            np.copyto(region_pixels, warped, where=mask[:, :, None] > 0)
        frame[y0:y1, x0:x1] = region_pixels


def encode_jpeg(image: Image, quality: int = JPEG_QUALITY) -> bytes:
    """``image`` (BGR) as JPEG bytes."""
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("OpenCV could not encode the frame as JPEG")
    return bytes(data)
