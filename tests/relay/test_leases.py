"""Relay leases on a real Redis: one holder per room however many pools race, and a lease that
is not renewed runs out so that another pool can take the room."""

from __future__ import annotations

import asyncio
import random
from collections.abc import AsyncIterator

import pytest
import redis.asyncio as aioredis

from app.relay.pool import RelayPool, RoomLeases
from app.server.fleet import keys
from tests.helpers.waiting import eventually


@pytest.fixture
async def redis(redis_url: str) -> AsyncIterator[aioredis.Redis]:
    client = aioredis.Redis.from_url(redis_url, decode_responses=True)
    yield client
    await client.aclose()


async def test_a_lease_that_is_not_renewed_runs_out_and_another_pool_takes_the_room(
    redis: aioredis.Redis,
) -> None:
    first, second = RoomLeases(redis, "pool-a", ttl_ms=400), RoomLeases(redis, "pool-b", 400)
    assert await first.claim("lab")
    assert not await second.claim("lab")
    # Renewed, the lease outlives its TTL...
    for _ in range(3):
        await asyncio.sleep(0.2)
        assert await first.renew("lab")
    assert not await second.claim("lab")
    # ...not renewed (a dead pool), it runs out and the room is free.
    await asyncio.sleep(0.6)
    assert await redis.get(keys.relay_lease("lab")) is None
    assert await second.claim("lab")
    # The old holder can neither renew nor release what is no longer its own.
    assert not await first.renew("lab")
    await first.release("lab")
    assert await redis.get(keys.relay_lease("lab")) == "pool-b"
    await second.release("lab")
    assert await redis.get(keys.relay_lease("lab")) is None


async def test_racing_pools_never_both_get_a_room(redis_url: str, redis: aioredis.Redis) -> None:
    rooms = [f"room-{i}" for i in range(20)]
    clients = [aioredis.Redis.from_url(redis_url, decode_responses=True) for _ in range(12)]
    pools = [RoomLeases(client, f"pool-{i}") for i, client in enumerate(clients)]

    async def claim_all(pool: RoomLeases, seed: int) -> list[str]:
        # Each pool walks the rooms in its own order, all pools at once, as real pools would.
        order = random.Random(seed).sample(rooms, len(rooms))
        return [room for room in order if await pool.claim(room)]

    try:
        won = await asyncio.gather(*(claim_all(pool, i) for i, pool in enumerate(pools)))
    finally:
        for client in clients:
            await client.aclose()
    holders: dict[str, list[str]] = {}
    for pool, rooms_won in zip(pools, won, strict=True):
        for room in rooms_won:
            holders.setdefault(room, []).append(pool.holder)
    assert {room: len(held) for room, held in holders.items()} == dict.fromkeys(rooms, 1)
    for room, [holder] in holders.items():
        assert await redis.get(keys.relay_lease(room)) == holder


async def test_a_pool_keeps_its_leases_while_its_pages_are_busy(
    redis_url: str, redis: aioredis.Redis
) -> None:
    # No tick runs here, as when opening a page takes longer than the lease: the pool's own
    # lease keeper alone holds the room, and it notices when another pool has it.
    pool = RelayPool("http://127.0.0.1:9", redis_url, pool_id="pool-a")
    pool.leases = RoomLeases(pool.redis, pool.id, ttl_ms=2500)
    assert await pool.leases.claim("lab")
    pool.held.add("lab")
    keeper = asyncio.create_task(pool._keep_leases())
    try:
        await asyncio.sleep(3.5)
        assert await redis.get(keys.relay_lease("lab")) == "pool-a"
        await redis.set(keys.relay_lease("lab"), "pool-b")
        await eventually(lambda: "lab" not in pool.held, 3, "the pool to see its lease lost")
    finally:
        keeper.cancel()
        await pool.redis.aclose()
