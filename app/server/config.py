"""All settings in one place: environment variables prefixed ``AUTOPILOT_``."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, ValidationError, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from app.protocol.ros import DEFAULT_FLAVOUR, RosFlavour
from app.protocol.signaling import IceServer
from app.protocol.tokens import check_secret
from app.resources import OPERATIONS_SPEC
from app.server.origins import normalise
from app.server.turn import TurnSettings
from app.simulators import DEFAULT_SIMULATOR, SimulatorName

__all__ = ["IceServer", "Settings", "describe_settings_error"]

# What a person sets is an environment variable: say it in those words, not pydantic's.
_TYPE_WORDS = {
    "int_parsing": "must be an integer",
    "int_from_float": "must be an integer",
    "float_parsing": "must be a number",
    "bool_parsing": "must be true or false",
}


class Settings(TurnSettings, BaseSettings):
    """Server configuration. Tests build one directly; the CLI reads the environment.

    The TURN/STUN fields come from :class:`TurnSettings` (``AUTOPILOT_TURN_URLS``,
    ``AUTOPILOT_STUN_URLS``, ``AUTOPILOT_TURN_SECRET``, ``AUTOPILOT_ICE_TRANSPORT_POLICY``,
    ``AUTOPILOT_TURN_CREDENTIAL_TTL_S``).
    """

    model_config = SettingsConfigDict(env_prefix="AUTOPILOT_", env_nested_delimiter="__")

    environment: Literal["development", "production"] = "development"
    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)
    # No public STUN by default: nothing leaves the machine unless an operator asks for it.
    # Extra ICE servers handed out as they are (TURN belongs in turn_urls: minted per login).
    ice_servers: list[IceServer] = Field(default_factory=list)
    # Signs the room- and role-scoped tokens (app.server.tokens); every login, /rosbridge
    # connection and state read must then carry one. Unset only in development.
    secret: str | None = Field(default=None, repr=False)
    # Origins besides the server's own whose pages may open /ws and /rosbridge.
    allowed_origins: list[str] = Field(default_factory=list)
    # The single shared login token of earlier versions; refused, so that an operator who still
    # sets it is told it no longer protects anything.
    token: str | None = Field(default=None, repr=False)
    # One policy for both WebSockets (/ws and /rosbridge), see app/server/websocket.py:
    # a larger frame is refused by uvicorn before it is buffered (close 1009) ...
    max_message_bytes: int = Field(default=64 * 1024, gt=0)
    # ... a peer leaving more than this unread is closed (1013) ...
    outbox_messages: int = Field(default=256, gt=0)
    outbox_bytes: int = Field(default=1024 * 1024, gt=0)
    # ... and these many sockets of each kind are served at once; more are closed with 1013.
    max_connections: int = Field(default=256, ge=1)
    max_rosbridge_sessions: int = Field(default=64, ge=1)
    # A connection that has not shown a token this long after opening is closed (1008): a /ws
    # login, or on /rosbridge (with AUTOPILOT_SECRET) an auth op or the handshake's token.
    login_timeout_s: float = Field(default=10.0, gt=0, allow_inf_nan=False)
    # Of each route's places, connections that have not shown a token yet hold at most these
    # many, and these many per client address; a newcomer takes the place of the oldest of
    # them, so they never keep out a peer that logs in (app/server/websocket.py).
    max_waiting_connections: int = Field(default=32, ge=1)
    max_waiting_per_address: int = Field(default=8, ge=1)
    # An HTTP request whose headers have not all arrived this long after it began is dropped.
    header_timeout_s: float = Field(default=10.0, gt=0, allow_inf_nan=False)
    # Without AUTOPILOT_SECRET, requests must name one of these hosts (besides 127.0.0.1,
    # localhost, [::1] and the address the server binds): a page on another name that a DNS
    # rebinding points here is refused (app/server/hosts.py).
    allowed_hosts: list[str] = Field(default_factory=list)
    operations_spec: Path = OPERATIONS_SPEC
    ros: RosFlavour = DEFAULT_FLAVOUR
    robot: SimulatorName = DEFAULT_SIMULATOR
    # When set (redis://host:port/db), instances sharing it form one signaling service
    # (app.server.fleet); unset, the hub runs embedded in this one process.
    redis_url: str | None = None

    @property
    def docs_enabled(self) -> bool:
        """The OpenAPI pages (/docs, /redoc, /openapi.json) are served in development only."""
        return self.environment == "development"

    @model_validator(mode="after")
    def _refuse_unsafe(self) -> Settings:
        if self.token is not None:
            raise ValueError(
                "AUTOPILOT_TOKEN is no longer used: set AUTOPILOT_SECRET and give each peer "
                "its own token from `autopilot token` (see docs/deploying.md)"
            )
        if self.environment == "production" and not self.secret:
            raise ValueError("AUTOPILOT_SECRET must be set when AUTOPILOT_ENVIRONMENT=production")
        if self.secret is not None:
            check_secret(self.secret)
        self.allowed_origins = [normalise(origin) for origin in self.allowed_origins]
        return self


def describe_settings_error(exc: ValidationError) -> str:
    """One line naming each bad setting by its environment variable, e.g. ``AUTOPILOT_PORT must
    be an integer``."""
    problems = []
    for error in exc.errors(include_url=False, include_input=False):
        loc, words = error["loc"], _TYPE_WORDS.get(error["type"])
        message = error["msg"].removeprefix("Value error, ")
        if not loc:  # a rule across settings: its message names them
            problems.append(message)
            continue
        name = f"AUTOPILOT_{str(loc[0]).upper()}"
        problems.append(f"{name} {words}" if words else f"{name}: {message}")
    return "; ".join(problems)
