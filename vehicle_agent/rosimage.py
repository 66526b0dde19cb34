"""A camera message's pixels: decoded, checked and fitted to the video's size (docs/camera.md).

:func:`to_rgb` turns a parsed ``sensor_msgs/CompressedImage`` (JPEG or PNG) or
``sensor_msgs/Image`` (``rgb8``, ``bgr8``, ``mono8``, rows of ``step`` bytes) into RGB pixels, or
raises :class:`ImageProblem` saying in one line what is wrong with it: an encoding the agent does
not read, data shorter or longer than its rows, a truncated or corrupt JPEG or PNG, a picture too
large to decode. :func:`letterbox` fits any size into the video's, its aspect kept.

Pure: numpy and OpenCV on bytes in memory, no I/O.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Final, Literal

import cv2
import numpy as np
import numpy.typing as npt

from app.protocol.camera import CameraImage, CompressedImage

Pixels = npt.NDArray[np.uint8]

# Raw encodings the agent reads: bytes per pixel, and the conversion to RGB (None: it is RGB).
ENCODINGS: Final[dict[str, tuple[int, int | None]]] = {
    "rgb8": (3, None),
    "bgr8": (3, cv2.COLOR_BGR2RGB),
    "mono8": (1, cv2.COLOR_GRAY2RGB),
}
# A picture with more pixels than this is refused before it is decoded: a 4096×4096 camera is
# already far past what the relay analyses, and a JPEG header may claim any size at all.
MAX_PIXELS: Final = 4096 * 4096

Codec = Literal["jpeg", "png"]
_MAGIC: Final[dict[Codec, bytes]] = {"jpeg": b"\xff\xd8\xff", "png": b"\x89PNG\r\n\x1a\n"}


class ImageProblem(ValueError):
    """A camera message whose pixels cannot be read; ``kind`` groups problems of one sort (so a
    reader can report each sort once), ``str(problem)`` says what is wrong."""

    def __init__(self, kind: str, text: str) -> None:
        super().__init__(text)
        self.kind = kind


@dataclass(frozen=True)
class Fit:
    """Where a ``width``×``height`` picture lands in the video: scaled to ``scaled`` and placed
    at ``offset`` (the bars around it are black)."""

    scaled: tuple[int, int]
    offset: tuple[int, int]


def to_rgb(image: CameraImage) -> Pixels:
    """The message's picture as RGB pixels (H×W×3), or :class:`ImageProblem`."""
    if isinstance(image, CompressedImage):
        return _decompress(image)
    channels, conversion = _encoding(image.encoding)
    width, height, step = image.width, image.height, image.step
    if width == 0 or height == 0:
        raise ImageProblem("size", f"an empty image ({width}x{height})")
    _check_pixels(width, height)
    row = width * channels
    if step < row:
        raise ImageProblem(
            "size", f"step {step} is shorter than a row of {width} {image.encoding} pixels ({row})"
        )
    if len(image.data) != step * height:
        raise ImageProblem(
            "size",
            f"data holds {len(image.data)} bytes, not height x step = {height} x {step}",
        )
    # Rows may be padded past their pixels (step > row): view each row's pixels only.
    rows = np.frombuffer(image.data, np.uint8).reshape(height, step)[:, :row]
    pixels = rows.reshape(height, width, channels)
    if conversion is None:
        return np.ascontiguousarray(pixels)
    return np.asarray(cv2.cvtColor(pixels, conversion), dtype=np.uint8)


def _encoding(encoding: str) -> tuple[int, int | None]:
    found = ENCODINGS.get(encoding)
    if found is None:
        readable = ", ".join(ENCODINGS)
        raise ImageProblem(
            "encoding", f"encoding {encoding!r} is not one the agent reads ({readable})"
        )
    return found


def codec_of(format_: str) -> Codec:
    """The codec a ``CompressedImage.format`` names: ``jpeg`` or ``png`` (``"jpeg"``, ``"png"``,
    or image_transport's ``"bgr8; jpeg compressed bgr8"``); :class:`ImageProblem` otherwise."""
    words = format_.lower().replace(";", " ").split()
    if "compresseddepth" in words:
        raise ImageProblem("format", f"format {format_!r} is a depth image, not a camera view")
    if "jpeg" in words or "jpg" in words:
        return "jpeg"
    if "png" in words:
        return "png"
    raise ImageProblem("format", f"format {format_!r} is neither jpeg nor png")


def _decompress(image: CompressedImage) -> Pixels:
    codec = codec_of(image.format)
    data = image.data
    if not data.startswith(_MAGIC[codec]):
        raise ImageProblem("corrupt", f"format {image.format!r}, but the data is no {codec}")
    size = encoded_size(codec, data)
    if size is None:
        raise ImageProblem("corrupt", f"the {codec} data has no picture header")
    _check_pixels(*size)
    decoded = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if decoded is None:
        raise ImageProblem(
            "corrupt", f"the {codec} data does not decode: truncated or corrupt ({len(data)} bytes)"
        )
    return np.asarray(cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB), dtype=np.uint8)


def _check_pixels(width: int, height: int) -> None:
    if width * height > MAX_PIXELS:
        raise ImageProblem(
            "size", f"a {width}x{height} picture is larger than the agent decodes ({MAX_PIXELS} px)"
        )


# JPEG's start-of-frame markers (baseline, progressive, ...): not DHT (C4), JPG (C8), DAC (CC).
_SOF_MARKERS: Final = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
# Markers that stand alone, without a length: TEM, RST0..7, SOI, EOI.
_STANDALONE: Final = frozenset({0x01, *range(0xD0, 0xDA)})


def encoded_size(codec: Codec, data: bytes) -> tuple[int, int] | None:
    """(width, height) from a JPEG's frame header or a PNG's IHDR, read without decoding;
    None when the header is missing or cut short."""
    if codec == "png":
        if len(data) < 24 or data[12:16] != b"IHDR":
            return None
        width, height = struct.unpack(">II", data[16:24])
        return int(width), int(height)
    at = 2
    while at + 4 <= len(data):
        if data[at] != 0xFF:
            return None
        marker = data[at + 1]
        if marker == 0xFF:  # a fill byte before the marker
            at += 1
            continue
        if marker in _STANDALONE:
            at += 2
            continue
        (length,) = struct.unpack(">H", data[at + 2 : at + 4])
        if marker in _SOF_MARKERS:
            if at + 9 > len(data):
                return None
            height, width = struct.unpack(">HH", data[at + 5 : at + 9])
            return int(width), int(height)
        at += 2 + length
    return None


def fit(width: int, height: int, size: tuple[int, int]) -> Fit:
    """How a ``width``×``height`` picture fits ``size``: as large as it goes, its aspect kept,
    centred."""
    out_w, out_h = size
    scale = min(out_w / width, out_h / height)
    scaled = (max(1, min(out_w, round(width * scale))), max(1, min(out_h, round(height * scale))))
    return Fit(scaled, ((out_w - scaled[0]) // 2, (out_h - scaled[1]) // 2))


def letterbox(rgb: Pixels, size: tuple[int, int]) -> Pixels:
    """``rgb`` fitted into a ``size`` frame (:func:`fit`), black bars where it does not reach."""
    height, width = rgb.shape[:2]
    if (width, height) == size:
        return rgb
    placed = fit(width, height, size)
    shrink = placed.scaled[0] < width
    scaled = cv2.resize(
        rgb, placed.scaled, interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR
    )
    frame = np.zeros((size[1], size[0], 3), np.uint8)
    x, y = placed.offset
    frame[y : y + placed.scaled[1], x : x + placed.scaled[0]] = scaled
    return frame
