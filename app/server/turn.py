"""TURN as users deploy it: the TURN REST credential scheme that coturn checks.

coturn started with ``use-auth-secret`` and ``static-auth-secret=SECRET`` accepts any username of
the form ``<expiry unix time>:<name>`` whose password is base64(HMAC-SHA1(SECRET, username)), until
the expiry passes. The server mints such a pair per login, so a page or an agent only ever holds a
password that stops working after ``credential_ttl_s``, never the shared secret.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
from typing import Self

from pydantic import BaseModel, Field, SecretStr, model_validator

from app.protocol.signaling import IceServer, IceTransportPolicy

__all__ = ["IceTransportPolicy", "TurnSettings", "ice_servers_for", "mint_turn_credentials"]


def mint_turn_credentials(secret: str, name: str, ttl_s: int, now: float) -> tuple[str, str]:
    """Return ``(username, password)`` valid for ``ttl_s`` seconds from ``now`` (unix time).

    ``name`` identifies who the credential was minted for (it shows in coturn's log); it may not
    contain ``:``, which separates the expiry from the name.
    """
    if ttl_s <= 0:
        raise ValueError(f"ttl_s must be positive, got {ttl_s}")
    if ":" in name:
        raise ValueError(f"name may not contain ':', got {name!r}")
    username = f"{int(now) + ttl_s}:{name}"
    digest = hmac.new(secret.encode(), username.encode(), hashlib.sha1).digest()
    return username, base64.b64encode(digest).decode("ascii")


class TurnSettings(BaseModel):
    """The TURN/STUN part of the settings; ``Settings`` inherits these fields.

    ``turn_urls`` and ``stun_urls`` are RTCIceServer ``urls`` (``turn:host:3478?transport=udp``,
    ``stun:host:3478``). With ``turn_urls`` set, ``turn_secret`` is coturn's
    ``static-auth-secret``. ``ice_transport_policy = "relay"`` makes every peer use relayed
    candidates only.
    """

    turn_urls: list[str] = Field(default_factory=list)
    stun_urls: list[str] = Field(default_factory=list)
    turn_secret: SecretStr | None = None
    ice_transport_policy: IceTransportPolicy = "all"
    turn_credential_ttl_s: int = Field(default=3600, gt=0)

    @model_validator(mode="after")
    def _check_turn(self) -> Self:
        if self.turn_urls and self.turn_secret is None:
            raise ValueError("TURN urls need the TURN shared secret (coturn static-auth-secret)")
        for url in self.turn_urls:
            if not url.startswith(("turn:", "turns:")):
                raise ValueError(f"a TURN url starts with turn: or turns:, got {url!r}")
        for url in self.stun_urls:
            if not url.startswith(("stun:", "stuns:")):
                raise ValueError(f"a STUN url starts with stun: or stuns:, got {url!r}")
        if self.ice_transport_policy == "relay" and not self.turn_urls:
            raise ValueError("ice_transport_policy 'relay' needs at least one TURN url")
        return self


def ice_servers_for(
    settings: TurnSettings, extra: list[IceServer], name: str, now: float
) -> list[IceServer]:
    """The ICE servers one login gets: STUN, TURN with credentials minted for ``name``, then
    ``extra`` as configured."""
    servers = [IceServer(urls=settings.stun_urls)] if settings.stun_urls else []
    if settings.turn_urls and settings.turn_secret is not None:
        username, password = mint_turn_credentials(
            settings.turn_secret.get_secret_value(),
            name.replace(":", "_"),
            settings.turn_credential_ttl_s,
            now,
        )
        servers.append(IceServer(urls=settings.turn_urls, username=username, credential=password))
    return servers + extra
