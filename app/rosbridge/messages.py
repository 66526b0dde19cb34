"""ROS messages as the simulator's rosbridge reads them: pydantic models, strict and closed.

As in rosbridge, unknown fields are an error and missing ones take their message's defaults;
numbers must be finite JSON numbers. ``geometry_msgs/Twist`` is what a turtle takes; the others
are the types of a robot description (:mod:`app.protocol.robot`) that the rosbridge carries
between its clients on topics the simulator does not own (:mod:`app.rosbridge.hosted`), but for
the camera's images, which :mod:`app.protocol.camera` reads. A header's time is spelled per
flavour -- ``secs``/``nsecs`` in ROS 1, ``sec``/``nanosec`` in ROS 2 -- and checked against the
flavour given as the validation context (``{"flavour": ...}``).
"""

from __future__ import annotations

from typing import Annotated, Final

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    StrictInt,
    StrictStr,
    ValidationInfo,
    model_validator,
)

from app.protocol.ros import RosFlavour

UInt32 = Annotated[StrictInt, Field(ge=0, le=2**32 - 1)]
Int32 = Annotated[StrictInt, Field(ge=-(2**31), le=2**31 - 1)]


class Payload(BaseModel):
    """A message or service payload: unknown fields are an error, numbers finite."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class Vector3(Payload):
    """``geometry_msgs/Vector3`` (and ``Point``); missing fields default to 0 as rosbridge fills
    them."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


class Twist(Payload):
    """``geometry_msgs/Twist``."""

    linear: Vector3 = Field(default_factory=Vector3)
    angular: Vector3 = Field(default_factory=Vector3)


class Time(Payload):
    """A header's stamp: ``secs``/``nsecs`` (ROS 1) or ``sec``/``nanosec`` (ROS 2)."""

    secs: Int32 | None = None
    nsecs: Int32 | None = None
    sec: Int32 | None = None
    nanosec: UInt32 | None = None

    @model_validator(mode="after")
    def _the_flavours_spelling(self, info: ValidationInfo) -> Time:
        flavour: RosFlavour | None = (info.context or {}).get("flavour")
        ros1 = (self.secs, self.nsecs) != (None, None)
        ros2 = (self.sec, self.nanosec) != (None, None)
        if flavour is not None and (ros1 if flavour != "1" else ros2):
            wanted = "secs and nsecs" if flavour == "1" else "sec and nanosec"
            raise ValueError(f"a ROS {flavour} time has {wanted}")
        return self


class Header(Payload):
    """``std_msgs/Header`` (``seq`` is ROS 1's only)."""

    seq: UInt32 | None = None
    stamp: Time = Field(default_factory=Time)
    frame_id: StrictStr = ""


class TwistStamped(Payload):
    """``geometry_msgs/TwistStamped``."""

    header: Header = Field(default_factory=Header)
    twist: Twist = Field(default_factory=Twist)


class Quaternion(Payload):
    """``geometry_msgs/Quaternion`` (the identity when left out)."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


class PoseMsg(Payload):
    """``geometry_msgs/Pose``."""

    position: Vector3 = Field(default_factory=Vector3)
    orientation: Quaternion = Field(default_factory=Quaternion)


Covariance = Annotated[list[float], Field(min_length=36, max_length=36)]


class PoseWithCovariance(Payload):
    """``geometry_msgs/PoseWithCovariance``."""

    pose: PoseMsg = Field(default_factory=PoseMsg)
    covariance: Covariance = Field(default_factory=lambda: [0.0] * 36)


class TwistWithCovariance(Payload):
    """``geometry_msgs/TwistWithCovariance``."""

    twist: Twist = Field(default_factory=Twist)
    covariance: Covariance = Field(default_factory=lambda: [0.0] * 36)


class Odometry(Payload):
    """``nav_msgs/Odometry``."""

    header: Header = Field(default_factory=Header)
    child_frame_id: StrictStr = ""
    pose: PoseWithCovariance = Field(default_factory=PoseWithCovariance)
    twist: TwistWithCovariance = Field(default_factory=TwistWithCovariance)


# The models by message type (``package/Name``).
MODELS: Final[dict[str, type[Payload]]] = {
    "geometry_msgs/Twist": Twist,
    "geometry_msgs/TwistStamped": TwistStamped,
    "nav_msgs/Odometry": Odometry,
}
