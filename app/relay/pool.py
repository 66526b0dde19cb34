"""``autopilot relay --pool``: one headless Chromium serving every room that needs a relay.

A room needs a relay when its member list (kept in Redis by the room's signaling owner, see
:mod:`app.server.fleet.bus`) has a vehicle and no relay. Pools compete for such rooms with a
Redis lease per room (``SET NX PX``, renewed every tick by its holder only): whoever sets the key
serves the room, so a room never gets two relays, however many pools race. A pool opens one relay
page per room it holds, in its one browser, and lets the room go (page closed, lease deleted)
once the room has neither a vehicle nor a client. A pool that dies stops renewing: its leases
expire after ``RELAY_LEASE_MS`` and the next tick of another pool takes the rooms.

Each page logs in with a relay token for its room: minted by the pool when it knows the
server's secret (``AUTOPILOT_SECRET``), else the one ``--token`` given (which admits to one room).

Each tick the pool also publishes every page's status (piloting, operation, goals/s, ms per
snapshot) under ``relay_status(room)`` for the ``/fleet`` page.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import socket
import subprocess
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import redis.asyncio as aioredis
from playwright.async_api import Browser, Page, async_playwright
from playwright.async_api import Error as PlaywrightError

from app.chromium import launch_options
from app.protocol import tokens
from app.relay.page import PAGE_LOAD_TIMEOUT_MS, RATE_WINDOW_S, loggable, relay_url
from app.resources import APP_DIR
from app.server.fleet import keys

log = logging.getLogger(__name__)

STATUS_JS = """(windowMs) => {
  const s = window.autopilotStatus;
  if (!s) return null;
  const now = performance.now();
  const ms = s.processingMs.slice(-15).sort((a, b) => a - b);
  return {
    piloting: s.piloting,
    op: s.op,
    vehicle: s.vehicle,
    clients: s.clients,
    goals_per_s: s.goalTimes.filter((t) => now - t <= windowMs).length / (windowMs / 1000),
    ms_per_snapshot: ms.length ? ms[Math.floor(ms.length / 2)] : null,
  };
}"""


class RoomLeases:
    """The relay leases of one pool: claim, renew and release, each atomic in Redis."""

    def __init__(self, redis: aioredis.Redis, holder: str, ttl_ms: int = keys.RELAY_LEASE_MS):
        self.redis, self.holder, self.ttl_ms = redis, holder, ttl_ms
        self._renew = redis.register_script(keys.RENEW_LUA)
        self._release = redis.register_script(keys.RELEASE_LUA)

    async def claim(self, room: str) -> bool:
        """Take the room if no pool holds it."""
        taken = await self.redis.set(keys.relay_lease(room), self.holder, nx=True, px=self.ttl_ms)
        return bool(taken)

    async def renew(self, room: str) -> bool:
        """Extend our lease; False if it ran out and someone else may hold the room now."""
        return bool(
            await self._renew(keys=[keys.relay_lease(room)], args=[self.holder, self.ttl_ms])
        )

    async def release(self, room: str) -> None:
        """Give the room up (only if we still hold it)."""
        await self._release(keys=[keys.relay_lease(room)], args=[self.holder])


async def room_members(redis: aioredis.Redis, room: str) -> list[dict[str, str]]:
    """``[{name, role}]`` of the room, in join order, from the owner's member list."""
    stored = await redis.hgetall(keys.room_members(room))
    entries = sorted((json.loads(value) for value in stored.values()), key=lambda e: int(e["seq"]))
    return [{"name": e["login"]["name"], "role": e["login"]["role"]} for e in entries]


async def rooms_needing_a_relay(redis: aioredis.Redis) -> list[str]:
    """Rooms with a vehicle and no relay, sorted by name."""
    needing = []
    for room in sorted(await redis.smembers(keys.ROOMS)):
        roles = {member["role"] for member in await room_members(redis, str(room))}
        if "vehicle" in roles and "relay" not in roles:
            needing.append(str(room))
    return needing


@dataclass
class _Served:
    page: Page
    dead: bool = False  # crashed or closed: reopened on the next tick while the lease holds


class RelayPool:
    """Claims rooms that need a relay and runs one relay page per room in one browser."""

    def __init__(
        self,
        server: str,
        redis_url: str,
        max_rooms: int | None = None,
        pool_id: str | None = None,
        profile: str = "default",
        name: str = "relay",
        secret: str | None = None,
        token: str | None = None,
        ca_file: Path | None = None,
    ) -> None:
        self.server, self.max_rooms, self.profile, self.name = server, max_rooms, profile, name
        # The relay token of each page: minted per room with the secret, else this one token.
        self.secret, self.token = secret, token
        self.launch_options = launch_options(trust_ca=ca_file)
        self.id = pool_id or f"{socket.gethostname()}-{os.getpid()}-{uuid.uuid4().hex[:6]}"
        self.redis: aioredis.Redis = aioredis.Redis.from_url(redis_url, decode_responses=True)
        self.leases = RoomLeases(self.redis, self.id)
        self.served: dict[str, _Served] = {}
        # Rooms whose lease this pool holds, renewed by their own task: opening a page or asking
        # one for its status can take longer than the lease under load, and must not lose it.
        self.held: set[str] = set()

    def pages(self) -> dict[str, Page]:
        """The live page of each room served, for the metrics' poll."""
        return {room: served.page for room, served in self.served.items() if not served.dead}

    async def run(self, stop: asyncio.Event) -> None:
        """Serve rooms until ``stop`` is set; then close every page and release every room."""
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(**self.launch_options)
            log.info("relay pool %s serving rooms of %s", self.id, self.server)
            keeper = asyncio.create_task(self._keep_leases())
            try:
                while not stop.is_set():
                    try:
                        if not browser.is_connected():
                            # Chromium died: its pages are marked dead and reopen in the new one.
                            log.warning("relay pool browser died; starting a new one")
                            browser = await playwright.chromium.launch(**self.launch_options)
                        await self.tick(browser)
                    except (aioredis.RedisError, PlaywrightError) as exc:
                        log.error("relay pool tick failed: %s", exc)
                    with contextlib.suppress(TimeoutError):
                        await asyncio.wait_for(stop.wait(), keys.TICK_S)
            finally:
                keeper.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await keeper
                for room in list(self.served):
                    await self._let_go(room)
                await browser.close()
                await self.redis.aclose()

    async def tick(self, browser: Browser) -> None:
        """Renew, report and let go of served rooms; then claim rooms that need a relay."""
        for room in list(self.served):
            if room not in self.held:
                await self._let_go(room, release=False)
                continue
            roles = {m["role"] for m in await room_members(self.redis, room)}
            if not roles & {"vehicle", "client"}:
                log.info("room %r is empty: letting it go", room)
                await self._let_go(room)
                continue
            served = self.served[room]
            if served.dead:
                log.warning("relay page of room %r died; opening it again", room)
                await self._close(served.page)
                self.served[room] = await self._open(browser, room)
            else:
                await self._report(room, served.page)
        for room in await rooms_needing_a_relay(self.redis):
            if self.max_rooms is not None and len(self.served) >= self.max_rooms:
                break
            if room not in self.served and await self.leases.claim(room):
                log.info("claimed room %r", room)
                self.held.add(room)
                self.served[room] = await self._open(browser, room)

    async def _keep_leases(self) -> None:
        """Renew every held lease each tick, whatever the pages are doing meanwhile."""
        while True:
            for room in list(self.held):
                try:
                    renewed = await self.leases.renew(room)
                except aioredis.RedisError as exc:
                    log.error("could not renew the relay lease of room %r: %s", room, exc)
                    continue  # kept until the lease is known lost: Redis may be back next tick
                if not renewed and room in self.held:
                    log.warning("lost the relay lease of room %r", room)
                    self.held.discard(room)
            await asyncio.sleep(keys.TICK_S)

    async def _open(self, browser: Browser, room: str) -> _Served:
        context = await browser.new_context()
        page = await context.new_page()
        served = _Served(page)

        def died(_: object) -> None:
            served.dead = True

        page.on("crash", died)
        page.on("close", died)
        page.on("pageerror", lambda error: log.warning("relay page %r error: %s", room, error))
        url = relay_url(self.server, room, self.name, self.profile, self.room_token(room))
        try:
            await page.goto(url, timeout=PAGE_LOAD_TIMEOUT_MS)
        except PlaywrightError as exc:
            log.warning("could not load %s: %s", loggable(url), exc.message.splitlines()[0])
            served.dead = True
        return served

    def room_token(self, room: str) -> str | None:
        """The relay token a page of ``room`` logs in with (None: the server asks for none)."""
        if self.secret is not None:
            return tokens.sign(self.secret, room, "relay", now=time.time())
        return self.token

    async def _report(self, room: str, page: Page) -> None:
        try:
            status: dict[str, Any] | None = await page.evaluate(STATUS_JS, RATE_WINDOW_S * 1000)
        except PlaywrightError as exc:
            log.debug("no status from room %r: %s", room, exc.message.splitlines()[0])
            return
        if status is not None:
            status["pool"] = self.id
            await self.redis.set(
                keys.relay_status(room), json.dumps(status), px=keys.RELAY_STATUS_TTL_MS
            )

    async def _let_go(self, room: str, release: bool = True) -> None:
        served = self.served.pop(room)
        held = room in self.held
        self.held.discard(room)
        await self._close(served.page)
        if release and held:
            with contextlib.suppress(aioredis.RedisError):
                await self.leases.release(room)
                await self.redis.delete(keys.relay_status(room))

    async def _close(self, page: Page) -> None:
        with contextlib.suppress(PlaywrightError):
            # The page's socket and peer connections close with it: the room sees the relay
            # leave.
            await page.close(run_before_unload=True)
            await page.context.close()


def start_pool_process(server_url: str, redis_url: str, log: Path) -> subprocess.Popen[bytes]:
    """Start ``autopilot relay --pool`` as its own process, output to ``log``.

    The fleet bench and the fleet test kill such a pool to watch another one take its rooms.
    """
    with log.open("wb") as out:
        return subprocess.Popen(
            [
                sys.executable,
                "-m",
                "app.cli",
                "relay",
                "--pool",
                "--server",
                server_url,
                "--redis-url",
                redis_url,
            ],
            cwd=APP_DIR.parent,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
