"""A robot camera's messages as a rosbridge carries them (docs/camera.md).

Two types: ``sensor_msgs/CompressedImage`` (``format`` names the codec: ``jpeg``, ``png``, or
image_transport's ``"bgr8; jpeg compressed bgr8"``) and ``sensor_msgs/Image`` (raw rows of
``step`` bytes in ``encoding``). Their ``data`` is a ``uint8[]``: rosbridge writes it as a
base64 string in JSON and as a byte string in CBOR (a subscription's ``compression: "cbor"``),
and takes a list of 0..255 integers from a publisher too. :class:`CameraImage` reads any of these
into ``bytes`` once. Headers come in either ROS spelling: ``seq`` and ``stamp.secs``/``nsecs``
(ROS 1) or ``stamp.sec``/``nanosec`` (ROS 2).

These models check a message's shape, as rosbridge does (a field of the wrong type, data that is
not base64); whether its pixels make sense (an encoding the agent reads, data as long as its rows)
is the reader's to decide (``vehicle_agent/rosimage.py``). Pure: no pixels are decoded here.
"""

from __future__ import annotations

import base64
import binascii
from typing import Annotated, Any, Final, Literal, get_args

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)

from app.protocol.errors import describe
from app.protocol.ros import RosFlavour, canonical

CameraType = Literal["sensor_msgs/CompressedImage", "sensor_msgs/Image"]
CAMERA_TYPES: Final[tuple[CameraType, ...]] = get_args(CameraType)
COMPRESSED_IMAGE: Final[CameraType] = "sensor_msgs/CompressedImage"
IMAGE: Final[CameraType] = "sensor_msgs/Image"
# image_transport's compressed topics end so; a raw image topic has no such suffix.
COMPRESSED_SUFFIX: Final = "/compressed"

UInt32 = Annotated[int, Field(ge=0, le=2**32 - 1)]


def camera_type(reported: str) -> CameraType | None:
    """The camera type ``reported`` names (rosapi's ``topic_type`` answer, in either spelling);
    None for any other type."""
    short = canonical(reported)
    for known in CAMERA_TYPES:
        if short == known:
            return known
    return None


def type_by_name(topic: str) -> CameraType:
    """The type a camera topic's name suggests: image_transport's ``.../compressed`` carries
    ``CompressedImage``, any other name a raw ``Image``."""
    return COMPRESSED_IMAGE if topic.rstrip("/").endswith(COMPRESSED_SUFFIX) else IMAGE


TypeSource = Literal["rosapi", "description", "name"]


class CameraTypeError(ValueError):
    """The camera topic carries a type that is no camera image."""


def choose_type(
    topic: str, reported: str | None, described: CameraType | None
) -> tuple[CameraType, TypeSource]:
    """The camera topic's type and where it came from: what the robot's rosapi reported (None
    or "" when it could not say), else the robot's description, else the topic's name
    (:func:`type_by_name`). A reported type that is no camera image is a
    :class:`CameraTypeError`."""
    if reported:
        kind = camera_type(reported)
        if kind is None:
            raise CameraTypeError(
                f"{topic} carries {reported}, not a camera image ({' or '.join(CAMERA_TYPES)})"
            )
        return kind, "rosapi"
    if described is not None:
        return described, "description"
    return type_by_name(topic), "name"


def _uint8_array(value: object) -> object:
    """``data`` as bytes: a base64 string (JSON), a byte string (CBOR) or a list of 0..255."""
    if isinstance(value, bytes | bytearray | memoryview):
        return bytes(value)
    if isinstance(value, str):
        try:
            return base64.b64decode(value, validate=True)
        except (binascii.Error, ValueError):
            raise ValueError("uint8[] data is a string that is not base64") from None
    if isinstance(value, list):
        if not all(type(v) is int and 0 <= v <= 255 for v in value):
            raise ValueError("uint8[] data as a list must hold integers 0..255")
        return bytes(value)
    raise ValueError("uint8[] data must be base64, a byte string or a list of 0..255")


Uint8Array = Annotated[bytes, BeforeValidator(_uint8_array)]


class _Msg(BaseModel):
    # Strict as rosbridge is: a string is not a number, a field it does not know is an error.
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class Stamp(_Msg):
    """``builtin_interfaces/Time`` (ROS 2: ``sec``, ``nanosec``) or ROS 1's ``time``
    (``secs``, ``nsecs``); missing fields are 0, as rosbridge fills them."""

    sec: int | None = None
    nanosec: UInt32 | None = None
    secs: int | None = None
    nsecs: UInt32 | None = None

    @model_validator(mode="after")
    def _one_spelling(self) -> Stamp:
        if (self.sec, self.nanosec) != (None, None) and (self.secs, self.nsecs) != (None, None):
            raise ValueError("a stamp is sec/nanosec (ROS 2) or secs/nsecs (ROS 1), not both")
        return self

    @property
    def parts(self) -> tuple[int, int]:
        """Whole seconds and nanoseconds, whichever spelling held them."""
        whole = self.sec if self.sec is not None else self.secs
        fraction = self.nanosec if self.nanosec is not None else self.nsecs
        return whole or 0, fraction or 0

    @property
    def seconds(self) -> float:
        """The stamp as seconds (since the epoch, on a robot that uses wall time)."""
        whole, fraction = self.parts
        return whole + fraction / 1e9


class Header(_Msg):
    """``std_msgs/Header``; ``seq`` is ROS 1's alone."""

    seq: UInt32 | None = None
    stamp: Stamp = Field(default_factory=Stamp)
    frame_id: str = ""


class CompressedImage(_Msg):
    """``sensor_msgs/CompressedImage``."""

    header: Header = Field(default_factory=Header)
    format: str = ""
    data: Uint8Array = b""


class Image(_Msg):
    """``sensor_msgs/Image``: ``height`` rows of ``step`` bytes, ``width`` pixels each."""

    header: Header = Field(default_factory=Header)
    height: UInt32 = 0
    width: UInt32 = 0
    encoding: str = ""
    is_bigendian: Annotated[int, Field(ge=0, le=255)] = 0
    step: UInt32 = 0
    data: Uint8Array = b""


CameraImage = CompressedImage | Image
MODELS: Final[dict[CameraType, type[CompressedImage] | type[Image]]] = {
    COMPRESSED_IMAGE: CompressedImage,
    IMAGE: Image,
}


def wire(image: CameraImage, flavour: RosFlavour) -> dict[str, Any]:
    """``image`` as a rosbridge of ``flavour`` sends it: every field, the header's stamp in the
    flavour's spelling (ROS 1 with its ``seq``), ``data`` as bytes (base64 in JSON, a byte string
    in CBOR)."""
    header = image.header
    whole, fraction = header.stamp.parts
    out_header: dict[str, Any]
    if flavour == "1":
        out_header = {
            "seq": header.seq or 0,
            "stamp": {"secs": whole, "nsecs": fraction},
            "frame_id": header.frame_id,
        }
    else:
        out_header = {"stamp": {"sec": whole, "nanosec": fraction}, "frame_id": header.frame_id}
    return {"header": out_header, **image.model_dump(exclude={"header"})}


class CameraMessageError(ValueError):
    """A message that is not the camera type it should be; ``str(error)`` names the fields."""


def parse(kind: CameraType, message: Any) -> CameraImage:
    """``message`` (rosbridge's ``msg``, from JSON or CBOR) as a ``kind``; raises
    :class:`CameraMessageError` naming every bad field."""
    try:
        return MODELS[kind].model_validate(message)
    except ValidationError as exc:
        raise CameraMessageError(f"not a {kind}: {describe(exc)}") from None
