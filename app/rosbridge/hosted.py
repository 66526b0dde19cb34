"""Topics the simulator does not own, carried between the rosbridge's clients, without any I/O.

A real rosbridge carries any topic of its robot's graph; this one simulates a robot (turtlesim,
or the diffdrive robot in its room), and besides that robot's own topics it hosts the topics of
the message types a robot description names (:mod:`app.protocol.robot`: ``Twist``,
``TwistStamped``, ``Odometry``, ``CompressedImage``, ``Image``), so that a test or a stand-in can
play another robot -- publish its ``/odom``, read the agent's ``/cmd_vel`` -- through the very
endpoint a vehicle drives.

A topic is hosted from the first ``advertise`` or typed ``subscribe`` that names it with one of
those types (in the served flavour's spelling) until no client advertises or subscribes to it
any more; its type is the one it was first given. Every message published on it is checked
against that type (:mod:`app.rosbridge.messages`; a camera image by :mod:`app.protocol.camera`,
its data read into bytes once) and kept, the latest few of each topic with a version number, for
its subscribers to take (the rosbridge's sessions pull what is newer than what they had): a
camera topic keeps its latest image only (a newer picture supersedes the older ones, and an
image is large). Any other type, or an untyped subscribe to a topic nobody hosts, is refused as
an unknown topic.
"""

from __future__ import annotations

import re
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Final

from pydantic import ValidationError

from app.protocol import camera
from app.protocol.errors import describe
from app.protocol.ros import RosFlavour, canonical, spell, spellings
from app.rosbridge.messages import MODELS

# At most this many hosted topics at once (each costs a dict entry, its kept messages and its
# subscribers' work).
MAX_HOSTED_TOPICS: Final = 64

# Every type a topic may be hosted with.
HOSTED_TYPES: Final[tuple[str, ...]] = (*MODELS, *camera.CAMERA_TYPES)

Versioned = tuple[int, dict[str, Any]]  # a message with its version: newer ones are larger

_NAME_RE = re.compile(r"/[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*\Z")


class HostingError(ValueError):
    """A topic that cannot be hosted, or a message that is not of its type."""


class MalformedMessage(HostingError):
    """A message that is not of its topic's type (a field missing, of the wrong type or out of
    range, a camera image's data that is not base64): malformed input, always answered."""


@dataclass(frozen=True)
class HostedTopic:
    """A hosted topic, by its absolute name."""

    name: str


@dataclass
class _Hosting:
    kind: str  # the message type, package/Name
    kept: deque[Versioned]  # the latest messages published on it, oldest first
    users: set[object] = field(default_factory=set)


class HostedTopics:
    """The hosted topics of one rosbridge hub, serving one flavour."""

    def __init__(self, flavour: RosFlavour, kept: int) -> None:
        self.flavour: RosFlavour = flavour
        # How many of each topic's latest messages are kept for subscribers that read slowly.
        self._kept = kept
        self._topics: dict[str, _Hosting] = {}
        # The version of the last message published on any hosted topic: one count for all, so
        # that a topic hosted again never gives out a version a subscription has seen.
        self._version = 0

    def types(self) -> dict[str, str]:
        """Every hosted topic and its type as the flavour spells it (for rosapi)."""
        return {name: spell(self.flavour, h.kind) for name, h in self._topics.items()}

    def find(self, name: str) -> HostedTopic | None:
        """The hosted topic ``name`` (leading slash optional), if it is hosted."""
        absolute = _absolute(name)
        return HostedTopic(absolute) if absolute in self._topics else None

    def claim(self, name: str, type_name: str | None, user: object) -> HostedTopic:
        """``user`` (a session) advertises or subscribes to ``name`` giving ``type_name``: the
        topic, hosted from now on if it was not; :class:`HostingError` if it cannot be."""
        absolute = _absolute(name)
        hosting = self._topics.get(absolute)
        if hosting is None:
            hosting = self._host(absolute, type_name)
        elif type_name is not None:
            spelled = spell(self.flavour, hosting.kind)
            if type_name not in spellings(self.flavour, spelled):
                raise HostingError(f"{name} has type {spelled}, not {type_name!r}")
        hosting.users.add(user)
        return HostedTopic(absolute)

    def release(self, topic: HostedTopic, user: object) -> None:
        """``user`` no longer advertises or subscribes to ``topic``; unhosted when nobody does."""
        hosting = self._topics.get(topic.name)
        if hosting is None:
            return
        hosting.users.discard(user)
        if not hosting.users:
            del self._topics[topic.name]

    def publish(self, topic: HostedTopic, msg: dict[str, Any]) -> None:
        """``msg`` published on ``topic``: checked against its type and kept (missing fields
        filled in) for its subscribers; :class:`MalformedMessage` naming the bad fields."""
        hosting = self._topics.get(topic.name)
        if hosting is None:
            raise HostingError(f"{topic.name} is no longer advertised")
        kind = hosting.kind
        message: dict[str, Any]
        if kind in camera.CAMERA_TYPES:
            try:
                image = camera.parse(kind, msg)
            except camera.CameraMessageError as exc:
                raise MalformedMessage(f"{topic.name}: {exc}") from None
            message = camera.wire(image, self.flavour)
        else:
            try:
                model = MODELS[kind].model_validate(msg, context={"flavour": self.flavour})
            except ValidationError as exc:
                raise MalformedMessage(f"{topic.name} ({kind}): {describe(exc)}") from None
            message = model.model_dump(exclude_none=True)
        self._version += 1
        hosting.kept.append((self._version, message))

    def version(self) -> int:
        """The current version: a new subscription takes only what is published after it."""
        return self._version

    def newer(self, topic: HostedTopic, seen: int) -> list[Versioned]:
        """``topic``'s kept messages newer than version ``seen``, oldest first."""
        hosting = self._topics.get(topic.name)
        if hosting is None:
            return []
        return [item for item in hosting.kept if item[0] > seen]

    def _host(self, absolute: str, type_name: str | None) -> _Hosting:
        hosted = ", ".join(HOSTED_TYPES)
        if type_name is None:
            raise HostingError(
                f"unknown topic {absolute!r}: no client advertises it; give its type to host "
                f"it ({hosted})"
            )
        kind = canonical(type_name)
        if kind not in HOSTED_TYPES or type_name not in spellings(
            self.flavour, spell(self.flavour, kind)
        ):
            raise HostingError(
                f"unknown topic {absolute!r}: this simulator hosts only topics of a robot's types "
                f"({hosted}, as ROS {self.flavour} spells them), not {type_name!r}"
            )
        if not _NAME_RE.match(absolute):
            raise HostingError(f"{absolute!r} is not a ROS topic name")
        if len(self._topics) >= MAX_HOSTED_TOPICS:
            raise HostingError(f"at most {MAX_HOSTED_TOPICS} hosted topics at once")
        # A camera keeps its latest picture only: latest wins, and an image is large.
        kept = 1 if kind in camera.CAMERA_TYPES else self._kept
        hosting = self._topics[absolute] = _Hosting(kind, deque(maxlen=kept))
        return hosting


def _absolute(name: str) -> str:
    return name if name.startswith("/") else f"/{name}"
