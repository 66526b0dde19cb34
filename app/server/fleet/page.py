"""``/fleet``: one row per room, live. ``/fleet/rooms`` is the same table as JSON.

Rows come from Redis when this instance is part of a fleet (every room of every instance: the
rooms set, each room's member list, its relay lease and the status its pool publishes), else
from the embedded hub (rooms of this process; no pool, so no piloting figures).

Access: with a secret configured, the rows (``/fleet/rooms``) need a token as ``Authorization:
Bearer`` (:func:`fleet_scope`): a token of a room (any role) sees that room's row alone; the whole
fleet needs a token made for it, ``autopilot token --role fleet``. The page sends the token in its
URL fragment (``/fleet#token=...``). The page itself holds no data and is served to anyone, like
the role pages.
"""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING, Annotated, Any
from urllib.parse import urlencode

from fastapi import APIRouter, Depends, HTTPException, Request, status
from fastapi.responses import HTMLResponse
from pydantic import BaseModel

from app.protocol import tokens
from app.protocol.tokens import TokenError, bearer_token
from app.server.fleet import keys
from app.server.pages import templates
from app.signaling.hub import Hub

if TYPE_CHECKING:  # the fleet extra: imported only where Redis is configured
    import redis.asyncio as aioredis

    from app.server.fleet.bus import FleetHub


# Who may see the rows: a room's peers (their own room) and fleet tokens (every room).
FLEET_VIEW_ROLES: tuple[tokens.TokenRole, ...] = (*tokens.ROLES, "fleet")


def fleet_scope(request: Request) -> str | None:
    """The one room whose row the request may see, or None for every room; 401 without a token
    when a secret is configured.

    The fleet table lists every room of the service, its peers and links: a room's token shows
    its own room, and only a fleet token (or no secret: development) shows them all.
    """
    secret: str | None = request.app.state.settings.secret
    if secret is None:
        return None
    token = bearer_token(request.headers)
    if token is None:
        refusal = (
            "send a token: Authorization: Bearer <token> (a room's token shows that room; "
            "autopilot token --role fleet makes one for every room)"
        )
    else:
        try:
            claims = tokens.verify(secret, token, now=time.time(), roles=FLEET_VIEW_ROLES)
        except TokenError as exc:
            refusal = str(exc)
        else:
            return None if claims.role == "fleet" else claims.room
    raise HTTPException(status.HTTP_401_UNAUTHORIZED, refusal, {"WWW-Authenticate": "Bearer"})


router = APIRouter()


class RoomRow(BaseModel):
    """One room of the fleet as the page shows it."""

    room: str
    vehicles: list[str]
    relay: str | None
    pool: str | None  # the relay pool serving the room, when its relay comes from one
    clients: list[str]
    piloting: bool | None  # None: unknown (a relay not run by a pool)
    op: str | None
    goals_per_s: float | None
    ms_per_snapshot: float | None
    client_url: str


def _row(room: str, members: list[dict[str, str]], status: dict[str, Any] | None) -> RoomRow:
    def named(role: str) -> list[str]:
        return [m["name"] for m in members if m["role"] == role]

    relays = named("relay")
    status = status or {}
    return RoomRow(
        room=room,
        vehicles=named("vehicle"),
        relay=relays[0] if relays else None,
        pool=status.get("pool"),
        clients=named("client"),
        piloting=status.get("piloting"),
        op=status.get("op"),
        goals_per_s=status.get("goals_per_s"),
        ms_per_snapshot=status.get("ms_per_snapshot"),
        client_url=f"/client?{urlencode({'room': room, 'name': 'client'})}",
    )


async def fleet_rows(redis: aioredis.Redis, only: str | None = None) -> list[RoomRow]:
    """Every room of the fleet (or the room ``only``, if it has anyone), by name, from Redis."""
    rows = []
    if only is None:
        names = sorted(str(r) for r in await redis.smembers(keys.ROOMS))
    else:
        names = [only] if await redis.sismember(keys.ROOMS, only) else []
    for room in names:
        stored = await redis.hgetall(keys.room_members(room))
        entries = sorted((json.loads(v) for v in stored.values()), key=lambda e: int(e["seq"]))
        members = [{"name": e["login"]["name"], "role": e["login"]["role"]} for e in entries]
        if not members:
            continue  # claimed a moment ago, or emptied and about to be released
        raw_status = await redis.get(keys.relay_status(room))
        rows.append(_row(room, members, json.loads(raw_status) if raw_status else None))
    return rows


def hub_rows(hub: Hub, only: str | None = None) -> list[RoomRow]:
    """Every room of the embedded hub (or the room ``only``, if it has anyone), by name."""
    names = sorted(hub.rooms()) if only is None else [r for r in hub.rooms() if r == only]
    return [_row(room, [p.model_dump() for p in hub.roster(room)], None) for room in names]


@router.get("/fleet/rooms")
async def fleet_rooms(
    request: Request, only: Annotated[str | None, Depends(fleet_scope)]
) -> list[RoomRow]:
    """The fleet table as JSON: the rooms the request's token may see."""
    hub: Hub | FleetHub = request.app.state.signaling.hub
    if isinstance(hub, Hub):
        return hub_rows(hub, only)
    return await fleet_rows(hub.redis, only)


@router.get("/fleet", response_class=HTMLResponse)
async def fleet_page(request: Request) -> HTMLResponse:
    """The fleet table, refreshed live by ``/static/js/pages/fleet.js``."""
    return templates.TemplateResponse(request, "fleet.html", {"refresh_ms": 1000})
