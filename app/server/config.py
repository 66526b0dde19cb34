"""All settings in one place: environment variables prefixed ``AUTOPILOT_``."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from app.resources import OPERATIONS_SPEC


class IceServer(BaseModel):
    """One entry of RTCConfiguration.iceServers, handed to every page and to the agent."""

    urls: list[str]
    username: str | None = None
    credential: str | None = None


class Settings(BaseSettings):
    """Server configuration. Tests build one directly; the CLI reads the environment."""

    model_config = SettingsConfigDict(env_prefix="AUTOPILOT_", env_nested_delimiter="__")

    environment: Literal["development", "production"] = "development"
    host: str = "127.0.0.1"
    port: int = 8000
    # No public STUN by default: nothing leaves the machine unless an operator asks for it.
    ice_servers: list[IceServer] = Field(default_factory=list)
    # When set, every login must carry this token.
    token: str | None = None
    max_message_bytes: int = 64 * 1024
    operations_spec: Path = OPERATIONS_SPEC
    sim_tick_s: float = 0.016
    # When set (redis://host:port/db), instances sharing it form one signaling service
    # (app.server.fleet); unset, the hub runs embedded in this one process.
    redis_url: str | None = None

    @model_validator(mode="after")
    def _refuse_unsafe(self) -> Settings:
        if self.environment == "production" and not self.token:
            raise ValueError("AUTOPILOT_TOKEN must be set when AUTOPILOT_ENVIRONMENT=production")
        return self
