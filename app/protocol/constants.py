"""Constants shared by the server, the agent, the tools and (through page config) the browser."""

from __future__ import annotations

from typing import Final, Literal

Role = Literal["vehicle", "relay", "client"]
ROLES: Final[tuple[Role, ...]] = ("vehicle", "relay", "client")

Profile = Literal["default", "thesis"]
# Relay and vehicle timing profiles: ``thesis`` reproduces the 2017 system's pacing.
PROFILES: Final[tuple[Profile, ...]] = ("default", "thesis")
DEFAULT_PROFILE: Final[Profile] = "default"
