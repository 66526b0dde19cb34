"""The data-channel messages as pydantic models (docs/architecture.md, "Data-channel messages").

One model per message ``type``; each direction of each channel accepts a tagged union of them
(:data:`RECEIVERS`). Numbers must be finite: JSON has no NaN or Infinity, and Python's ``json``
module would otherwise let them through. Models are strict (a string is not a number) and allow
extra fields, so a newer peer may add one without breaking an older one. The browser validates
against JSON Schemas generated from these same models (:func:`channel_schemas`).

The vehicle opens two channels to the relay (docs/architecture.md, "Lossy links").
``autopilot`` is reliable and ordered: mode commands (``stop``) and error reports, which must
arrive. ``autopilot-state`` is unordered and never retransmits: goals (relay -> vehicle), pose and
frame capture times (vehicle -> relay) are state, only the newest matters, and a lost one is
better skipped than waited for (no head-of-line blocking on a lossy link). The vehicle applies a
goal only if its ``seq`` is newer than every goal applied on this link and it is not stale
(``vehicle_agent/core/freshness.py``, ``app/static/js/core/freshness.js``). The client's ``control``
channel is reliable.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, Final, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError

from app.protocol import jsonedge
from app.protocol.errors import describe
from app.protocol.rooms import Role

# The labels of the data channels: the vehicle opens ``autopilot`` (reliable) and
# ``autopilot-state`` (lossy, goals and pose) to the relay, the client opens ``control`` to it.
AUTOPILOT_CHANNEL: Final = "autopilot"
AUTOPILOT_STATE_CHANNEL: Final = "autopilot-state"
CONTROL_CHANNEL: Final = "control"

# RTCDataChannelInit of the state channel (aiortc takes the same two keyword arguments).
STATE_CHANNEL_ORDERED: Final = False
STATE_CHANNEL_MAX_RETRANSMITS: Final = 0
# The most frame capture times one ``frameTimes`` message carries.
MAX_FRAME_TIMES: Final = 64
# A goal that took this much longer than the quickest goal of the last GOAL_AGE_WINDOW_S on its
# way is stale and dropped.
GOAL_MAX_AGE_S: Final = 0.5
GOAL_AGE_WINDOW_S: Final = 5.0
# A goal stamped more than this ahead of the vehicle's wall clock comes from the future and is
# refused: the relay's and the vehicle's clocks must agree within it (docs/architecture.md).
GOAL_MAX_CLOCK_SKEW_S: Final = 60.0
# A relay numbers its goals one by one, at most one per analysed frame: a goal's seq runs ahead
# of the last applied on its link by at most GOAL_SEQ_BURST plus GOAL_SEQ_RATE_HZ per second since
# then, and never past GOAL_SEQ_MAX (beyond it a page's counter no longer counts). A goal
# numbered beyond that reach is refused: it would hold back every real goal after it.
GOAL_SEQ_RATE_HZ: Final = 120.0
GOAL_SEQ_BURST: Final = 120
GOAL_SEQ_MAX: Final = 2**53 - 1

Finite = Annotated[float, Field(allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Count = Annotated[int, Field(ge=0)]
# A frame wider or taller than this is not a camera frame (8K is 7680 wide).
MAX_FRAME_SIDE: Final = 16_384
Size = Annotated[int, Field(gt=0, le=MAX_FRAME_SIDE)]
# A box's side in pixels (a colour region's may be fractional once scaled).
BoxSide = Annotated[float, Field(gt=0, le=MAX_FRAME_SIDE, allow_inf_nan=False)]
# A target's real height (m): no operation finds anything taller than a building.
Height = Annotated[float, Field(gt=0, le=100, allow_inf_nan=False)]
OpId = Annotated[str, Field(min_length=1, max_length=64)]


class _Message(BaseModel):
    model_config = ConfigDict(extra="allow", strict=True, frozen=True)


class Goal(_Message):
    """relay→vehicle: steer toward pixel (x, y) of a w×h frame; ``t`` is the relay's ms clock.

    ``boxW``×``boxH`` is the target's box in pixels of that frame, and ``targetHeightM`` the real
    height its operation declares for what the box spans (``app/vision/operations.json``): with
    the camera's field of view they give a camera carried by the vehicle the target's range
    (the onboard law). A relay that sends neither leaves that law turning without driving.
    ``locked``: the target is the one the operator locked on, not the largest box (a relay that
    does not say is taken as unlocked).
    """

    type: Literal["goal"] = "goal"
    seq: Annotated[int, Field(ge=1, le=GOAL_SEQ_MAX)]
    op: OpId
    x: Finite
    y: Finite
    w: Size
    h: Size
    t: Finite
    # The frame tag of the analysed frame, when the video carries one.
    frame: Count | None = None
    boxW: BoxSide | None = None  # noqa: N815 -- the wire name
    boxH: BoxSide | None = None  # noqa: N815 -- the wire name
    targetHeightM: Height | None = None  # noqa: N815 -- the wire name
    locked: bool = False


# What a vehicle's search for a lost target is doing (the onboard and follow profiles): turning
# toward the side the target was last seen on, or ``timed_out``: it ran out and the vehicle
# stopped, and waits for the target (until a goal, a stop or a mode change).
SearchStatus = Literal["left", "right", "timed_out"]


class Pose(_Message):
    """vehicle→relay, and relay→client as forwarded: the turtle's pose in terrain metres, and
    how its search for a lost target stands (None: not searching)."""

    type: Literal["pose"] = "pose"
    x: Finite
    y: Finite
    theta: Finite
    t: Finite | None = None
    # Milliseconds since the vehicle last applied a goal (None: none on this link yet).
    goalAgeMs: NonNegative | None = None  # noqa: N815 -- the wire name
    search: SearchStatus | None = None


class FrameTime(_Message):
    """When the vehicle's camera handed frame number ``frame`` (its frame tag) to the encoder:
    ``t`` in Unix milliseconds on the vehicle's clock."""

    frame: Count
    t: Finite


class FrameTimes(_Message):
    """vehicle→relay on the state channel, and relay→client as forwarded: the capture times of
    the tagged frames sent since the last such message. A client that reads the tag of a frame
    it shows subtracts its capture time from the moment it showed it: glass to glass. The
    clocks are the vehicle's and the client's (docs/contracts.md, "Glass to glass")."""

    type: Literal["frameTimes"] = "frameTimes"
    frames: Annotated[list[FrameTime], Field(min_length=1, max_length=MAX_FRAME_TIMES)]


class Stop(_Message):
    """relay→vehicle: piloting stopped, zero at once; client→relay: stop piloting."""

    type: Literal["stop"] = "stop"


class Start(_Message):
    """client→relay: start piloting (signaling is the normal path, as in the thesis)."""

    type: Literal["start"] = "start"


class GetOps(_Message):
    """client→relay: ask for the operations (answered with ``ops`` then ``state``)."""

    type: Literal["getOps"] = "getOps"


class SetOp(_Message):
    """client→relay: use this operation from the next snapshot on."""

    type: Literal["setOp"] = "setOp"
    op: OpId


class OpInfo(_Message):
    """One operation the relay offers."""

    id: OpId
    label: str
    description: str


class Ops(_Message):
    """relay→client: the operations, in spec order, and the current one."""

    type: Literal["ops"] = "ops"
    ops: list[OpInfo]
    current: OpId | None = None


class State(_Message):
    """relay→client: whether piloting, with which operation, and the vehicle's name."""

    type: Literal["state"] = "state"
    piloting: bool
    op: OpId | None
    vehicle: str | None


class Point(_Message):
    """A pixel of the analysed frame."""

    x: Finite
    y: Finite


Box = Annotated[list[Finite], Field(min_length=4, max_length=4)]


class Detections(_Message):
    """relay→client: what one snapshot found, with the relay's statistics riding along."""

    type: Literal["detections"] = "detections"
    op: OpId
    boxes: list[Box]  # [x, y, w, h] in pixels of the w×h frame
    target: Point | None
    w: Size
    h: Size
    ms: NonNegative  # this snapshot's processing delay: taken -> goal sent
    goalsPerS: NonNegative  # noqa: N815 -- the wire name
    # The locked target's box, when a lock holds and this snapshot found it.
    locked: Box | None = None
    # The last full scan's boxes: between full scans ``boxes`` holds only what the tracker's
    # window found, and these are the other targets a click can lock (app/protocol/lock.py).
    candidates: list[Box] | None = None


# Of the relay's target lock (app/protocol/lock.py): none: the largest box is the target; locked:
# seen on the last snapshot; lost: not seen, looked for near where it was; searching: lost long
# enough to be looked for in the whole frame.
LockState = Literal["none", "locked", "lost", "searching"]


class Lock(_Message):
    """client→relay: lock on the target at or near pixel (x, y) of the analysed frame (the rule:
    app/protocol/lock.py); a point where nothing is found releases the lock."""

    type: Literal["lock"] = "lock"
    x: Finite
    y: Finite


class Unlock(_Message):
    """client→relay: release the lock (back to the largest box)."""

    type: Literal["unlock"] = "unlock"


class LockStatus(_Message):
    """relay→client: the lock changed state; ``box`` is the locked target's, ``reason`` says
    why it was released."""

    type: Literal["lockState"] = "lockState"
    state: LockState
    box: Box | None = None
    reason: str | None = None


# Manual override: "auto", the relay's goals steer; "manual", the operator's drive commands do.
Mode = Literal["auto", "manual"]
# A drive command's share of the vehicle profile's manual speed (docs/architecture.md, "Who
# holds the wheel").
Axis = Annotated[float, Field(ge=-1, le=1, allow_inf_nan=False)]
PeerName = Annotated[str, Field(min_length=1, max_length=64)]


class TakeOver(_Message):
    """client→relay: this client takes the wheel (refused while another operator holds it)."""

    type: Literal["takeOver"] = "takeOver"


class HandBack(_Message):
    """client→relay: the operator gives the wheel back to the autopilot."""

    type: Literal["handBack"] = "handBack"


class Drive(_Message):
    """client→relay, relay→vehicle: the operator's command; ``linear`` forward (+) / back (−)
    and ``angular`` counter-clockwise (+) / clockwise (−), each a share of the profile's manual
    speed. ``seq`` grows with every command of one sender (the relay renumbers what it
    forwards); a command that is not the newest is dropped."""

    type: Literal["drive"] = "drive"
    seq: Annotated[int, Field(ge=1)]
    linear: Axis
    angular: Axis


class ModeChange(_Message):
    """relay→vehicle and relay→clients: who steers now; ``operator`` is the client holding the
    wheel in manual mode, ``reason`` why the mode changed."""

    type: Literal["mode"] = "mode"
    mode: Mode
    operator: PeerName | None = None
    reason: str | None = None


class StopRobot(_Message):
    """client→relay: stop the robot at once, whoever holds the wheel: piloting stops and an
    operator's wheel goes back to the autopilot (any client may send it)."""

    type: Literal["stopRobot"] = "stopRobot"


class RobotStopped(_Message):
    """relay→clients: the robot was stopped; ``by`` the client who pressed Stop robot, or None
    when the relay stopped piloting because no client was watching; ``reason`` in words. Sent
    to every client, and to a client that connects while the stop still stands."""

    type: Literal["robotStopped"] = "robotStopped"
    by: PeerName | None = None
    reason: str


CandidateType = Literal["host", "srflx", "prflx", "relay"]


class LinkFigures(_Message):
    """One link's received video as its receiver's getStats() showed it over the last period;
    None where the browser did not say."""

    rttMs: NonNegative | None  # noqa: N815 -- the wire names
    lossPct: Annotated[float, Field(ge=0, le=100, allow_inf_nan=False)] | None  # noqa: N815
    fps: NonNegative | None
    width: Count | None
    height: Count | None
    candidate: CandidateType | None  # the selected pair's: relay if either end is, and so on


class Health(_Message):
    """relay→client, once a link-health period: the vehicle→relay link as the relay measures it."""

    type: Literal["health"] = "health"
    link: LinkFigures


class Error(_Message):
    """Any peer→any peer: why a message was refused; ``ref`` is its type, if known."""

    type: Literal["error"] = "error"
    reason: str
    ref: str | None = None


ChannelMessage = (
    Goal
    | Pose
    | FrameTimes
    | Stop
    | Start
    | GetOps
    | SetOp
    | Ops
    | State
    | Detections
    | Lock
    | Unlock
    | LockStatus
    | TakeOver
    | HandBack
    | Drive
    | ModeChange
    | StopRobot
    | RobotStopped
    | Health
    | Error
)


def _or(models: tuple[type[_Message], ...]) -> Any:
    union: Any = models[0]
    for model in models[1:]:
        union = union | model
    return union


# What each side accepts on each channel: RECEIVERS[label][receiving role].
RECEIVERS: Final[dict[str, dict[Role, tuple[type[_Message], ...]]]] = {
    # Goals fall back to the reliable channel while the state channel is not open.
    # Drive commands, like goals, are state: the lossy channel when it is open.
    AUTOPILOT_CHANNEL: {
        "vehicle": (Goal, Stop, ModeChange, Drive, Error),
        "relay": (Pose, Error),
    },
    # Capture times, like pose, are state: only the lossy channel carries them.
    AUTOPILOT_STATE_CHANNEL: {
        "vehicle": (Goal, Drive, Error),
        "relay": (Pose, FrameTimes, Error),
    },
    CONTROL_CHANNEL: {
        "relay": (
            GetOps,
            SetOp,
            Start,
            Stop,
            StopRobot,
            Lock,
            Unlock,
            TakeOver,
            HandBack,
            Drive,
            Error,
        ),
        "client": (
            Ops,
            State,
            Detections,
            Pose,
            FrameTimes,
            LockStatus,
            ModeChange,
            RobotStopped,
            Health,
            Error,
        ),
    },
}


def type_of(model: type[_Message]) -> str:
    """The ``type`` a model's messages carry."""
    value: str = get_args(model.model_fields["type"].annotation)[0]
    return value


_adapters: dict[tuple[str, Role], TypeAdapter[Any]] = {
    (label, role): TypeAdapter(Annotated[_or(models), Field(discriminator="type")])
    for label, by_role in RECEIVERS.items()
    for role, models in by_role.items()
}


@dataclass(frozen=True)
class Refused:
    """A data-channel text that is not a message this side accepts; ``ref`` is its type."""

    reason: str
    ref: str | None


def parse(text: str | bytes, label: str, role: Role) -> ChannelMessage | Refused:
    """Parse one data-channel message received by ``role`` on channel ``label``; whatever the
    text holds (a 5000-digit number, NaN, deep nesting), a :class:`Refused` says why not."""
    try:
        data = jsonedge.loads(text)
    except jsonedge.JsonEdgeError as exc:
        return Refused(str(exc), None)
    return validate(data, label, role)


def validate(data: Any, label: str, role: Role) -> ChannelMessage | Refused:
    """Validate an already-decoded JSON value as a message ``role`` accepts on ``label``."""
    if not isinstance(data, dict) or not isinstance(data.get("type"), str):
        return Refused("expected a JSON object with a string field 'type'", None)
    kind = data["type"]
    accepted = {type_of(model) for model in RECEIVERS[label][role]}
    if kind not in accepted:
        return Refused(f"unknown message type {kind!r} on channel {label!r}", kind)
    try:
        message: ChannelMessage = _adapters[label, role].validate_python(data)
    except ValidationError as exc:
        # The first element of loc is the union tag (the message type); the rest is the field.
        return Refused(f"bad {kind}: {describe(exc, skip=1)}", kind)
    return message


def dump(message: ChannelMessage) -> str:
    """The JSON text of a message, as it goes on the wire."""
    return message.model_dump_json()


def channel_schemas() -> dict[str, dict[str, dict[str, Any]]]:
    """JSON Schema of what each role accepts on each channel: ``[label][role]``."""
    return {
        label: {role: _adapters[label, role].json_schema() for role in by_role}
        for label, by_role in RECEIVERS.items()
    }
