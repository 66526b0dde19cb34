"""All settings in one place: environment variables prefixed ``AUTOPILOT_``."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from app.protocol.signaling import IceServer
from app.resources import OPERATIONS_SPEC
from app.server.turn import TurnSettings

__all__ = ["IceServer", "Settings"]


class Settings(TurnSettings, BaseSettings):
    """Server configuration. Tests build one directly; the CLI reads the environment.

    The TURN/STUN fields come from :class:`TurnSettings` (``AUTOPILOT_TURN_URLS``,
    ``AUTOPILOT_STUN_URLS``, ``AUTOPILOT_TURN_SECRET``, ``AUTOPILOT_ICE_TRANSPORT_POLICY``,
    ``AUTOPILOT_TURN_CREDENTIAL_TTL_S``).
    """

    model_config = SettingsConfigDict(env_prefix="AUTOPILOT_", env_nested_delimiter="__")

    environment: Literal["development", "production"] = "development"
    host: str = "127.0.0.1"
    port: int = 8000
    # No public STUN by default: nothing leaves the machine unless an operator asks for it.
    # Extra ICE servers handed out as they are (TURN belongs in turn_urls: minted per login).
    ice_servers: list[IceServer] = Field(default_factory=list)
    # When set, every login must carry this token.
    token: str | None = None
    max_message_bytes: int = 64 * 1024
    operations_spec: Path = OPERATIONS_SPEC
    sim_tick_s: float = 0.016

    @model_validator(mode="after")
    def _refuse_unsafe(self) -> Settings:
        if self.environment == "production" and not self.token:
            raise ValueError("AUTOPILOT_TOKEN must be set when AUTOPILOT_ENVIRONMENT=production")
        return self
