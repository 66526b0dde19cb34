"""Generated test frames: faces pasted into scenes, flame-coloured blobs, clip samples.

Everything is drawn from a seeded generator so a failing frame can be regenerated exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from app.resources import OPERATIONS_SPEC
from app.vision.reference import detect
from app.vision.spec import load_spec

# Public face images and a clip (MIT licence: tests/data/faces/README.md), kept in the repository.
FACES = Path(__file__).resolve().parents[1] / "data" / "faces"
CLIP = FACES / "short_hamilton_clip.mp4"

Bgr = npt.NDArray[np.uint8]


@dataclass(frozen=True)
class Placed:
    """Where a face or blob was drawn: (x, y, w, h) in frame pixels."""

    x: int
    y: int
    w: int
    h: int

    @property
    def centre(self) -> tuple[float, float]:
        """Centre of the drawn region."""
        return self.x + self.w / 2, self.y + self.h / 2


def to_rgba(bgr: Bgr) -> npt.NDArray[np.uint8]:
    """An OpenCV BGR image as the RGBA frame the analyzer sees."""
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGBA)


def background(rng: np.random.Generator, width: int, height: int) -> Bgr:
    """A plain, gradient or noisy background in a random colour."""
    style = rng.integers(3)
    colour = rng.integers(20, 235, size=3)
    frame = np.empty((height, width, 3), np.uint8)
    frame[:] = colour
    if style == 1:
        ramp = np.linspace(0.4, 1.2, width)[None, :, None]
        frame = np.clip(frame * ramp, 0, 255).astype(np.uint8)
    elif style == 2:
        noise = rng.normal(0, 18, size=frame.shape)
        frame = np.clip(frame + noise, 0, 255).astype(np.uint8)
    return frame


def face_crop(name: str = "obama.jpg") -> Bgr:
    """The largest face of a photo in tests/data/faces, with a margin (found with Python OpenCV)."""
    image = cv2.imread(str(FACES / name))
    spec = load_spec(OPERATIONS_SPEC)
    found = detect(spec.op("face"), to_rgba(image))
    x, y, w, h = max(found.boxes, key=lambda b: b[2] * b[3])
    m = w // 3
    return image[max(0, y - m) : y + h + m, max(0, x - m) : x + w + m].copy()


def paste_face(
    rng: np.random.Generator, frame: Bgr, crop: Bgr, *, mirror: bool, angle: float
) -> Placed:
    """Paste ``crop`` at a random size, place and brightness; returns where it went."""
    height, width = frame.shape[:2]
    size = int(rng.integers(min(height, width) // 5, min(height, width) * 3 // 4))
    face = cv2.resize(crop, (size, size), interpolation=cv2.INTER_AREA)
    if mirror:
        face = face[:, ::-1]
    if angle:
        turn = cv2.getRotationMatrix2D((size / 2, size / 2), angle, 1.0)
        face = cv2.warpAffine(face, turn, (size, size), borderMode=cv2.BORDER_REFLECT)
    gain = rng.uniform(0.6, 1.4)
    face = np.clip(face.astype(np.float32) * gain, 0, 255).astype(np.uint8)
    x = int(rng.integers(0, width - size + 1))
    y = int(rng.integers(0, height - size + 1))
    frame[y : y + size, x : x + size] = face
    return Placed(x, y, size, size)


def draw_flame(rng: np.random.Generator, frame: Bgr, placed: Placed | None = None) -> Placed:
    """A flame-coloured blob: an orange ellipse with a yellow core and ragged noise."""
    height, width = frame.shape[:2]
    if placed is None:
        w = int(rng.integers(width // 10, width // 4))
        h = int(rng.integers(height // 8, height // 3))
        placed = Placed(int(rng.integers(0, width - w)), int(rng.integers(0, height - h)), w, h)
    centre = (placed.x + placed.w // 2, placed.y + placed.h // 2)
    cv2.ellipse(frame, centre, (placed.w // 2, placed.h // 2), 0, 0, 360, (0, 90, 255), -1)
    cv2.ellipse(frame, centre, (placed.w // 4, placed.h // 4), 0, 0, 360, (40, 210, 255), -1)
    region = frame[placed.y : placed.y + placed.h, placed.x : placed.x + placed.w]
    noise = rng.normal(0, 10, size=region.shape)
    region[:] = np.clip(region + noise, 0, 255).astype(np.uint8)
    return placed


def clip_frames(count: int) -> list[Bgr]:
    """``count`` frames spread evenly over the clip."""
    capture = cv2.VideoCapture(str(CLIP))
    total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    frames: list[Bgr] = []
    for index in np.linspace(0, total - 1, count).astype(int):
        capture.set(cv2.CAP_PROP_POS_FRAMES, int(index))
        ok, frame = capture.read()
        if ok:
            frames.append(frame)
    capture.release()
    return frames


def clip_stills(indices: Sequence[int]) -> list[Bgr]:
    """The clip's frames at ``indices`` (0-based), read in order from the first: a seek may land
    on a neighbouring frame."""
    wanted = set(indices)
    capture = cv2.VideoCapture(str(CLIP))
    found: dict[int, Bgr] = {}
    index = 0
    while len(found) < len(wanted):
        ok, frame = capture.read()
        if not ok:
            break
        if index in wanted:
            found[index] = frame
        index += 1
    capture.release()
    missing = wanted - found.keys()
    if missing:
        raise ValueError(f"{CLIP.name} has no frames {sorted(missing)}")
    return [found[i] for i in indices]


def write_generated_frames(folder: Path, seed: int = 4) -> list[Path]:
    """Every generated frame of the parity test as PNG in ``folder``; returns their paths."""
    rng = np.random.default_rng(seed)
    written: list[Path] = []

    def save(name: str, frame: Bgr) -> None:
        path = folder / f"{name}.png"
        cv2.imwrite(str(path), frame)
        written.append(path)

    crops = [face_crop(n) for n in ("obama.jpg", "biden.jpg", "rose_leslie1.jpg")]
    sizes = [(640, 480), (1280, 720), (480, 640)]
    for i in range(12):
        width, height = sizes[i % len(sizes)]
        frame = background(rng, width, height)
        paste_face(
            rng,
            frame,
            crops[i % len(crops)],
            mirror=bool(i % 2),
            angle=float(rng.uniform(-12, 12)) if i % 3 == 0 else 0.0,
        )
        save(f"face-{i:02d}", frame)
    for i in range(3):
        save(f"noface-{i}", background(rng, 640, 480))
    for i in range(6):
        frame = background(rng, *sizes[i % 2])
        draw_flame(rng, frame)
        save(f"flame-{i}", frame)
    for i, frame in enumerate(clip_frames(4)):
        save(f"clip-{i}", frame)
    return written
