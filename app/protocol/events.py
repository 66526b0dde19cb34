"""The vehicle's event records: what it did and when, one frozen dataclass per kind.

An event log line is ``{"ev": kind, <the fields>, "t": seconds}`` (:func:`record`); ``t`` is the
recording process's clock, given by whoever made the event (the agent's ``time.monotonic()``,
comparable across processes of one machine; the vehicle page's ``performance.now() / 1000``).
The pilot's kinds (:data:`PilotEvent`: goal, goal_dropped, mode, drive, twist, search,
search_ended) are made by the
pilot core of each vehicle (``vehicle_agent/core/pilot.py`` and its twin
``app/static/js/core/pilot.js``), so both vehicles record the same records.

Who reads them: the agent's JSON-lines log (``vehicle_agent/events.py``), its flight recorder and
``autopilot replay`` (topics and schemas in ``app/recording.py``), its metrics
(``vehicle_agent/metrics.py``) and the bench (``app/tools/bench``). Pure data: no I/O here.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, ClassVar, Literal, TypeVar, get_args

from pydantic import ConfigDict, TypeAdapter, ValidationError

from app.protocol.channels import Mode

# Why a goal was not applied: not newer than the last (``old``), sent too long ago (``stale``),
# numbered or stamped beyond what its link can have reached (``future``), or the operator holds
# the wheel (``manual``).
DropReason = Literal["old", "stale", "future", "manual"]
LinkState = Literal["offer", "up", "down"]
# What a frame's time is: when the synthetic scene drew it (``render``), the camera message's
# header stamp (``stamp``), or when the message arrived, its stamp missing or not believable
# (``receipt``).
CaptureClock = Literal["render", "stamp", "receipt"]


@dataclass(frozen=True, kw_only=True)
class Event:
    """What every event has: its kind (the log's ``ev``) and when it happened (``t``)."""

    kind: ClassVar[str]
    # How a record is read back (:func:`from_json`): strictly, as the channels' models are -- a
    # log that says "1" where a number belongs is broken, not something to guess at; fields a
    # later version added are ignored.
    __pydantic_config__: ClassVar[ConfigDict] = ConfigDict(strict=True, extra="ignore")
    t: float


@dataclass(frozen=True, kw_only=True)
class FrameSent(Event):
    """A frame handed to the encoder, ``frame`` its tag; ``t`` is when its picture was taken.

    A synthetic frame carries the true face centre in pixels (``face_x``, ``face_y``; None for a
    camera's frame, whose truth nobody knows); ``jump`` is true on the first frame after the
    face leapt across the frame (``SweepPath.jump_times``). ``capture`` says what ``t`` is
    (:data:`CaptureClock`).
    """

    kind: ClassVar[str] = "frame_sent"
    frame: int
    face_x: float | None = None
    face_y: float | None = None
    jump: bool = False
    capture: CaptureClock = "render"


@dataclass(frozen=True, kw_only=True)
class GoalApplied(Event):
    """A goal received and applied: it steers the turtle now."""

    kind: ClassVar[str] = "goal"
    seq: int
    op: str
    frame: int | None
    x: float
    y: float
    w: float
    h: float
    # The target's box in pixels of the w×h frame, when the relay sent one.
    box_w: float | None = None
    box_h: float | None = None
    # The target is the one the operator locked on (the relay's goal said so).
    locked: bool = False


@dataclass(frozen=True, kw_only=True)
class GoalDropped(Event):
    """A goal received and not applied, and why (:data:`DropReason`)."""

    kind: ClassVar[str] = "goal_dropped"
    seq: int
    frame: int | None
    why: DropReason


@dataclass(frozen=True, kw_only=True)
class ModeChanged(Event):
    """The operator took the wheel (``manual``, with their name) or handed it back (``auto``)."""

    kind: ClassVar[str] = "mode"
    mode: Mode
    operator: str | None


@dataclass(frozen=True, kw_only=True)
class DriveReceived(Event):
    """An operator's drive command: ``applied`` unless refused (auto mode, an old seq);
    ``moving`` when it made the turtle move."""

    kind: ClassVar[str] = "drive"
    seq: int
    applied: bool
    moving: bool


@dataclass(frozen=True, kw_only=True)
class TwistSent(Event):
    """A Twist published to the turtle: ``seq``/``frame`` of the goal that caused it, None for a
    stop or an operator's command."""

    kind: ClassVar[str] = "twist"
    seq: int | None
    frame: int | None
    linear: float
    angular: float


# Which way a search turns: toward the side the target was last seen on.
Side = Literal["left", "right"]
# How a search ended: a goal came back (``found``), its time ran out and the vehicle stopped
# (``timed_out``), or piloting stopped meanwhile (``stopped``: the relay's stop, a mode change, a
# lost link).
SearchEnd = Literal["found", "timed_out", "stopped"]


@dataclass(frozen=True, kw_only=True)
class SearchStarted(Event):
    """The target was lost (no goal for the profile's ``search_after_s``): the vehicle stopped
    driving and turns toward the ``side`` it was last seen on to find it."""

    kind: ClassVar[str] = "search"
    side: Side


@dataclass(frozen=True, kw_only=True)
class SearchEnded(Event):
    """A search ended, ``after_s`` after it started, and how (:data:`SearchEnd`)."""

    kind: ClassVar[str] = "search_ended"
    why: SearchEnd
    after_s: float


@dataclass(frozen=True, kw_only=True)
class PoseReport(Event):
    """The turtle's pose as the vehicle saw it; ``sent`` when it went to the relay as
    telemetry."""

    kind: ClassVar[str] = "pose"
    x: float
    y: float
    theta: float
    sent: bool


@dataclass(frozen=True, kw_only=True)
class LinkChanged(Event):
    """The connection to the relay offered, up (with ``local_candidates``: the candidate types
    gathered, and ``selected``: this side's type in the nominated pair, if known) or down (with
    ``reason``)."""

    kind: ClassVar[str] = "link"
    state: LinkState
    relay: str
    reason: str | None = None
    local_candidates: tuple[str, ...] = ()
    selected: str | None = None


@dataclass(frozen=True, kw_only=True)
class SpawnStep(Event):
    """The spawn step turned the turtle (``x``, ``y``, ``theta``) or failed (``reason``)."""

    kind: ClassVar[str] = "spawn"
    ok: bool
    x: float | None = None
    y: float | None = None
    theta: float | None = None
    reason: str | None = None


@dataclass(frozen=True, kw_only=True)
class RecorderTotals(Event):
    """The flight recorder's totals when it stopped: what it recorded, the items it dropped,
    camera frames seen and held, and its own CPU seconds (``cpu_s`` = ``loop_cpu_s`` +
    ``writer_cpu_s``) over ``seconds`` of recording."""

    kind: ClassVar[str] = "recorder"
    images: int
    messages: int
    dropped: int
    files: int
    frames: int
    frames_held: int
    cpu_s: float
    loop_cpu_s: float
    writer_cpu_s: float
    seconds: float


AnyEvent = (
    FrameSent
    | GoalApplied
    | GoalDropped
    | ModeChanged
    | DriveReceived
    | TwistSent
    | SearchStarted
    | SearchEnded
    | PoseReport
    | LinkChanged
    | SpawnStep
    | RecorderTotals
)
KINDS: dict[str, type[Event]] = {cls.kind: cls for cls in get_args(AnyEvent)}
# What a vehicle's pilot makes, in both languages (vehicle_agent/core/pilot.py, core/pilot.js).
PilotEvent = (
    GoalApplied
    | GoalDropped
    | ModeChanged
    | DriveReceived
    | TwistSent
    | SearchStarted
    | SearchEnded
)


E = TypeVar("E", bound=Event)


class EventError(ValueError):
    """A record that is not an event: not JSON, an unknown ``ev``, or not its kind's fields."""


def of_kind(events: Iterable[Event], kind: type[E]) -> list[E]:
    """The events of one kind, in order."""
    return [event for event in events if isinstance(event, kind)]


def _field_names(cls: type[Event]) -> list[str]:
    """The kind's field names, ``t`` last (the order of a log line)."""
    names = [f.name for f in dataclasses.fields(cls) if f.name != "t"]
    return [*names, "t"]


def record(event: Event) -> dict[str, Any]:
    """``event`` as a log line's object: ``ev``, its fields, ``t``."""
    return {"ev": event.kind, **{name: getattr(event, name) for name in _field_names(type(event))}}


def from_json(line: str | bytes) -> AnyEvent:
    """The event of one log line (:func:`record` as JSON); :class:`EventError` if it is not one."""
    try:
        data = json.loads(line)
    except ValueError as exc:
        raise EventError(f"not JSON: {exc}") from exc
    kind = data.get("ev") if isinstance(data, dict) else None
    cls = KINDS.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise EventError(f"unknown event kind {kind!r}; known: {sorted(KINDS)}")
    return from_fields(cls, line)


def from_fields(cls: type[Event], text: str | bytes) -> AnyEvent:
    """An event of kind ``cls`` from a JSON object of its fields (a log line, or a recorded
    message, which has no ``ev``); :class:`EventError` if they are not its fields."""
    try:
        event: AnyEvent = _adapter(cls).validate_json(text)
    except ValidationError as exc:
        raise EventError(f"not a {cls.kind!r} event: {exc}") from exc
    return event


def _adapter(cls: type[Event]) -> TypeAdapter[Any]:
    # Built on first use: most processes never read a record back.
    adapter = _ADAPTERS.get(cls)
    if adapter is None:
        adapter = _ADAPTERS[cls] = TypeAdapter(cls)
    return adapter


_ADAPTERS: dict[type[Event], TypeAdapter[Any]] = {}
