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
    # One policy for both WebSockets (/ws and /rosbridge), see app/server/websocket.py:
    # a larger frame is refused by uvicorn before it is buffered (close 1009) ...
    max_message_bytes: int = Field(default=64 * 1024, gt=0)
    # ... a peer leaving more than this unread is closed (1013) ...
    outbox_messages: int = Field(default=256, gt=0)
    outbox_bytes: int = Field(default=1024 * 1024, gt=0)
    # ... and these many sockets of each kind are served at once; more are closed with 1013.
    max_connections: int = Field(default=256, ge=1)
    max_rosbridge_sessions: int = Field(default=64, ge=1)
    # A /ws connection that has not logged in this long after opening is closed (1008).
    login_timeout_s: float = Field(default=10.0, gt=0)
    operations_spec: Path = OPERATIONS_SPEC

    @model_validator(mode="after")
    def _refuse_unsafe(self) -> Settings:
        if self.environment == "production" and not self.token:
            raise ValueError("AUTOPILOT_TOKEN must be set when AUTOPILOT_ENVIRONMENT=production")
        return self
