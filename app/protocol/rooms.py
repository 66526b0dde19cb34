"""Rooms and the roles a peer takes in one: a vehicle, a relay and its clients."""

from __future__ import annotations

from typing import Final, Literal

# The room a peer joins when it names none.
DEFAULT_ROOM: Final = "default"

Role = Literal["vehicle", "relay", "client"]
ROLES: Final[tuple[Role, ...]] = ("vehicle", "relay", "client")
