"""Signaling across instances: the unchanged :class:`~app.signaling.core.Hub`, carried over Redis.

Design (docs/scaling.md has the long form):

- **One owner per room.** Each room is run by exactly one instance, the holder of the Redis lease
  ``room_owner(room)`` (SET NX PX, renewed every tick). The owner keeps one ordinary ``Hub`` for
  that room, so rosters, relay rules, ``from`` stamping and error replies are the hub's own.
- **Global connection ids.** A socket is ``<instance id>/<local id>``. The instance holding the
  socket forwards its frames for the room to the owner's pub/sub channel; the owner maps global
  ids to its hub's ids and publishes each resulting ``Outgoing``/``Close`` to the channel of the
  instance holding the target socket, which puts it on that socket's outbox.
- **Pre-login frames stay local.** Until a frame parses as a ``login``, an instance answers it
  with a local hub (the *lobby*) that never has anyone logged in: the same replies as one
  instance. A ``login`` goes to its room's owner; a refused login sends the socket back to the
  lobby.
- **Liveness is TTL keys.** Each instance renews ``instance(id)`` every tick. An owner that finds
  a member's instance key gone disconnects that member in its hub, which tells the others exactly
  as a closed socket would. An instance whose room has lost its owner lease claims the room and
  rebuilds it from the member list the owner keeps in Redis (``room_members``): it replays every
  member's login, in join order, into a fresh hub and throws those replies away (the survivors
  already know each other), then disconnects the members whose instance is dead, which sends the
  survivors the same ``leave`` and roster messages a single instance would.
- **No lost frames across a failover.** Publishing to a dead owner reaches nobody (PUBLISH
  returns 0); the socket's frames wait and are sent again to the new owner, in order.

:class:`FleetHub` has the hub's transport API (``connect``/``receive``/``receive_binary``/
``disconnect``). Actions it can decide at once are returned; the rest arrive later through
``deliver``, which the switchboard sets to its ``dispatch``.
"""

from __future__ import annotations

import asyncio
import json
import logging
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import redis.asyncio as aioredis
from redis.asyncio.client import Pipeline, PubSub

from app.protocol.rooms import Role
from app.protocol.signaling import IceServer, IceTransportPolicy, Login, ParseError, parse
from app.protocol.tokens import Claims
from app.server.config import Settings
from app.server.fleet import keys
from app.server.signaling import login_ice
from app.signaling.hub import Action, Census, Close, ConnId, Hub, HubMetrics, Outgoing

log = logging.getLogger(__name__)

# How long a socket's frames wait for a room owner before they are dropped (a failover takes
# at most ROOM_LEASE_MS + TICK_S).
OWNER_WAIT_S = 10.0
# A frame forwarded to an instance that no longer owns the room is sent on at most this often.
MAX_HOPS = 3
# Redis connections the sockets' pumps may use at once (the client's pool holds 100).
PUMP_CONNECTIONS = 64
# The most queued commands the owner sends to Redis in one pipeline.
PUBLISH_BATCH = 500

Deliver = Callable[[list[Action]], None]
Ice = Callable[[str], tuple[list[IceServer], IceTransportPolicy]]


def _drop(actions: list[Action]) -> None:
    log.warning("fleet hub has no switchboard yet; dropping %d actions", len(actions))


@dataclass
class _Local:
    """A socket on this instance."""

    id: ConnId
    # The room its frames go to: set when a login is forwarded, cleared when it is refused.
    room: str | None = None
    # Set when the owner's reply says its login succeeded (the login deadline asks).
    logged_in: bool = False
    closing: bool = False
    queue: asyncio.Queue[dict[str, Any]] = field(default_factory=asyncio.Queue)
    pump: asyncio.Task[None] | None = None


@dataclass
class _Room:
    """A room this instance owns: its hub and the map between global and hub connection ids."""

    name: str
    hub: Hub
    hub_ids: dict[str, ConnId] = field(default_factory=dict)  # global -> hub
    global_ids: dict[ConnId, str] = field(default_factory=dict)  # hub -> global
    members: set[str] = field(default_factory=set)  # global ids logged in
    seq: int = 0  # join order, kept in the member list
    entries: dict[str, dict[str, Any]] = field(default_factory=dict)  # global id -> its entry

    def hub_id(self, conn: str) -> ConnId:
        hub_conn = self.hub_ids.get(conn)
        if hub_conn is None:
            hub_conn = self.hub.connect()
            self.hub_ids[conn] = hub_conn
            self.global_ids[hub_conn] = conn
        return hub_conn

    def forget(self, conn: str) -> list[Action]:
        hub_conn = self.hub_ids.pop(conn, None)
        self.members.discard(conn)
        self.entries.pop(conn, None)
        if hub_conn is None:
            return []
        del self.global_ids[hub_conn]
        return self.hub.disconnect(hub_conn)


class FleetHub:
    """This instance's part of a fleet-wide hub; same transport API as ``Hub``."""

    def __init__(
        self,
        redis_url: str,
        secret: str | None = None,
        ice: Ice | None = None,
        max_message_bytes: int = 64 * 1024,
        instance_id: str | None = None,
    ) -> None:
        self.id = instance_id or uuid.uuid4().hex[:12]
        # Each room's hub checks the logins' tokens with the secret and mints their ICE.
        self.secret = secret
        self.ice = ice
        self.max_message_bytes = max_message_bytes
        self.deliver: Deliver = _drop
        self.redis: aioredis.Redis = aioredis.Redis.from_url(redis_url, decode_responses=True)
        # Every socket's pump talks to Redis at once under load, and the client's pool refuses
        # its 101st concurrent command: pumps take turns for a share of it instead.
        self._pump_slots = asyncio.Semaphore(PUMP_CONNECTIONS)
        self._lobby = Hub(secret=secret, ice=ice, max_message_bytes=max_message_bytes)
        # What this instance's hubs (the lobby's and its rooms') count; set by the app.
        self._metrics: HubMetrics | None = None
        self._locals: dict[ConnId, _Local] = {}
        self._owned: dict[str, _Room] = {}
        # Rooms emptied here whose lease is still being given back (see _release_room).
        self._releasing: set[str] = set()
        # Owner of each room our sockets are in, as last seen (saves a GET per frame).
        self._owners: dict[str, str] = {}
        # Owner -> other instances, in order: one task publishes them all.
        self._outbound: asyncio.Queue[tuple[str, Any]] = asyncio.Queue()
        self._tasks: list[asyncio.Task[None]] = []
        self._pubsub: PubSub | None = None
        self._forwarding: set[asyncio.Task[None]] = set()
        self._pumps: set[asyncio.Task[None]] = set()
        self._renew_many = self.redis.register_script(keys.RENEW_MANY_LUA)
        self._release = self.redis.register_script(keys.RELEASE_LUA)

    @classmethod
    def from_settings(cls, settings: Settings) -> FleetHub:
        """A fleet hub on ``settings.redis_url`` with the settings' secret, ICE and size limit."""
        if settings.redis_url is None:
            raise ValueError("FleetHub needs AUTOPILOT_REDIS_URL")
        return cls(
            settings.redis_url, settings.secret, login_ice(settings), settings.max_message_bytes
        )

    @property
    def metrics(self) -> HubMetrics | None:
        """Told of the frames and refusals of the lobby and of every room this instance owns."""
        return self._metrics

    @metrics.setter
    def metrics(self, metrics: HubMetrics | None) -> None:
        self._metrics = self._lobby.metrics = metrics
        for owned in self._owned.values():
            owned.hub.metrics = metrics

    def census(self) -> Census:
        """The rooms this instance owns and their peers (each room has one owner in the fleet,
        so the instances' censuses add up to the fleet's)."""
        peers: dict[Role, int] = {}
        for owned in self._owned.values():
            for role, count in owned.hub.census().peers.items():
                peers[role] = peers.get(role, 0) + count
        return Census(len(self._owned), peers)

    # -- lifecycle ------------------------------------------------------------------------------

    async def start(self) -> None:
        """Announce this instance and listen on its channel; returns once messages can arrive."""
        await self.redis.set(keys.instance(self.id), self.id, px=keys.INSTANCE_TTL_MS)
        self._pubsub = self.redis.pubsub()
        await self._pubsub.subscribe(keys.inbox(self.id))
        self._tasks = [
            asyncio.create_task(self._listen(self._pubsub), name=f"fleet-listen-{self.id}"),
            asyncio.create_task(self._publish(), name=f"fleet-publish-{self.id}"),
            asyncio.create_task(self._watch(), name=f"fleet-watch-{self.id}"),
        ]
        log.info("fleet instance %s joined via Redis", self.id)

    async def stop(self) -> None:
        """Leave the fleet: rooms and peers of this instance are taken over or told at once."""
        # Pumps of closed sockets may still be sending their last frames: stop them all.
        running = [*self._tasks, *self._pumps, *self._forwarding]
        for task in running:
            task.cancel()
        await asyncio.gather(*running, return_exceptions=True)
        try:
            await self.redis.delete(keys.instance(self.id))
            for room in list(self._owned):
                await self._release(keys=[keys.room_owner(room)], args=[self.id])
        except aioredis.RedisError as exc:
            log.warning("could not leave the fleet cleanly (others will time us out): %s", exc)
        finally:
            if self._pubsub is not None:
                await self._pubsub.aclose()  # type: ignore[no-untyped-call]  # untyped in redis-py
            await self.redis.aclose()

    # -- the hub's transport API ----------------------------------------------------------------

    def connect(self) -> ConnId:
        """Register a new socket and return its (local) id."""
        conn = self._lobby.connect()
        local = _Local(conn)
        local.pump = asyncio.create_task(self._pump(local), name=f"fleet-pump-{conn}")
        self._pumps.add(local.pump)
        local.pump.add_done_callback(self._pumps.discard)
        self._locals[conn] = local
        return conn

    def logged_in(self, conn: ConnId) -> bool:
        """True once the room's owner has accepted ``conn``'s login."""
        local = self._locals.get(conn)
        return local is not None and local.logged_in

    def receive(self, conn: ConnId, text: str) -> list[Action]:
        """A text frame from a local socket: answered by the lobby or forwarded to the owner."""
        local = self._locals[conn]
        if local.closing:
            return []
        if local.room is None:
            login = _as_login(text, self.max_message_bytes)
            if login is None:
                return self._lobby.receive(conn, text)
            local.room = login.room
        local.queue.put_nowait({"room": local.room, "text": text})
        return []

    def receive_binary(self, conn: ConnId) -> list[Action]:
        """A binary frame: refused, by the lobby or by the room's hub (which counts it)."""
        local = self._locals[conn]
        if local.closing:
            return []
        if local.room is None:
            return self._lobby.receive_binary(conn)
        local.queue.put_nowait({"room": local.room, "binary": True})
        return []

    def expire(self) -> list[Action]:
        """End the sessions whose token has expired in the rooms this instance owns; what that
        sends goes out through ``deliver``, like everything an owner sends."""
        for owned in list(self._owned.values()):
            actions = owned.hub.expire()
            if actions:
                self._settle(owned, actions, None, None)
        return []

    def disconnect(self, conn: ConnId) -> list[Action]:
        """The socket is gone: its room's owner hears it as a closed socket."""
        local = self._locals.pop(conn, None)
        actions = self._lobby.disconnect(conn)
        if local is not None:
            if local.room is not None:
                local.queue.put_nowait({"room": local.room, "gone": True})
            else:
                local.queue.put_nowait({"stop": True})
        return actions

    # -- socket side: forward frames to the owner ----------------------------------------------

    def _global(self, conn: ConnId) -> str:
        return f"{self.id}/{conn}"

    async def _pump(self, local: _Local) -> None:
        """Forward one socket's frames to its room's owner, in order."""
        while True:
            item = await local.queue.get()
            if item.get("stop"):
                return
            op = {"op": "room", "conn": self._global(local.id), **item}
            try:
                async with self._pump_slots:
                    await self._to_owner(item["room"], op, hops=0)
            except aioredis.RedisError as exc:
                log.error("cannot forward a frame of %s: %s", local.id, exc)
            if item.get("gone"):
                return

    async def _to_owner(self, room: str, op: dict[str, Any], hops: int) -> None:
        """Hand ``op`` to the owner of ``room``, claiming the room if it has none."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + OWNER_WAIT_S
        while True:
            owned = self._owned.get(room)
            if owned is not None:
                self._on_room_op(owned, op)
                return
            message = json.dumps({**op, "hops": hops + 1})
            cached = self._owners.get(room)
            if cached is not None and hops < MAX_HOPS:
                # One round trip per frame: a stale owner still forwards it on (see _listen).
                if await self.redis.publish(keys.inbox(cached), message) > 0:
                    return
                self._owners.pop(room, None)  # dead: ask Redis who owns the room now
            owner = _text(await self.redis.get(keys.room_owner(room)))
            if owner == self.id and room in self._releasing:
                # Emptied a moment ago and the lease is still ours: run it again, empty as it
                # was (its member list may still hold entries about to be deleted).
                self._releasing.discard(room)
                owned = self._new_room(room)
                self._owned[room] = owned
                self._on_room_op(owned, op)
                return
            if owner is None:
                owned = await self._claim(room)
                if owned is not None:
                    self._on_room_op(owned, op)
                    return
                continue  # another instance claimed it first: send it there
            if owner != self.id and hops < MAX_HOPS:
                if await self.redis.publish(keys.inbox(owner), message) > 0:
                    self._owners[room] = owner
                    return
            # The owner is dead (nobody heard), is us while we still rebuild, or bounces it.
            if loop.time() > deadline:
                log.warning(
                    "no owner for room %r within %.0f s; dropped %s", room, OWNER_WAIT_S, op
                )
                return
            await asyncio.sleep(0.1)

    async def _forward(self, op: dict[str, Any]) -> None:
        """A frame that reached us after we gave its room up: on to the room's owner."""
        try:
            async with self._pump_slots:
                await self._to_owner(op["room"], op, op["hops"])
        except aioredis.RedisError as exc:
            log.error("cannot forward a frame of %s: %s", op["conn"], exc)

    # -- owner side -----------------------------------------------------------------------------

    async def _claim(self, room: str) -> _Room | None:
        """Take the room's lease if it is free; then rebuild the room from its member list."""
        taken = await self.redis.set(keys.room_owner(room), self.id, nx=True, px=keys.ROOM_LEASE_MS)
        if not taken:
            return None
        owned = self._new_room(room)
        await self.redis.sadd(keys.ROOMS, room)
        stored = await self.redis.hgetall(keys.room_members(room))
        members = sorted(
            ((str(_text(conn)), json.loads(value)) for conn, value in stored.items()),
            key=lambda item: int(item[1]["seq"]),
        )
        # Replay the logins in join order; the survivors already know each other, so the
        # replies are dropped. Their tokens were checked when they logged in (and are not
        # stored): the replay runs with no secret, then it is back, and each session is given
        # the claims it had, so that it still ends when they expire. Nor are the logins
        # counted again as frames.
        owned.hub.secret, owned.hub.metrics = None, None
        try:
            for conn, entry in members:
                hub_conn = owned.hub_id(conn)
                owned.hub.receive(hub_conn, json.dumps(entry["login"]))
                if entry.get("claims") is not None:
                    owned.hub.restore(hub_conn, Claims(**entry["claims"]))
                owned.members.add(conn)
                owned.entries[conn] = entry
                owned.seq = max(owned.seq, int(entry["seq"]) + 1)
        finally:
            owned.hub.secret, owned.hub.metrics = self.secret, self._metrics
        self._owned[room] = owned
        if members:
            log.info("took over room %r with %d members", room, len(members))
            await self._drop_dead_members([owned])
        return owned

    def _new_room(self, room: str) -> _Room:
        hub = Hub(
            secret=self.secret,
            ice=self.ice,
            max_message_bytes=self.max_message_bytes,
            metrics=self._metrics,
        )
        return _Room(room, hub)

    def _on_room_op(self, owned: _Room, op: dict[str, Any]) -> None:
        """One forwarded frame or disconnect of ``op['conn']`` through the room's hub."""
        conn: str = op["conn"]
        if op.get("gone"):
            if conn in owned.hub_ids:
                self._remove_member(owned, conn)
            return
        hub_conn = owned.hub_id(conn)
        if op.get("binary"):
            actions = owned.hub.receive_binary(hub_conn)
        else:
            actions = owned.hub.receive(hub_conn, op["text"])
        self._settle(owned, actions, conn, op.get("text"))

    def _remove_member(self, owned: _Room, conn: str) -> None:
        """``conn``'s socket is gone: what the hub does for a closed socket."""
        actions = owned.forget(conn)
        self._left(owned, conn)
        self._settle(owned, actions, None, None)

    def _settle(
        self, owned: _Room, actions: list[Action], sender: str | None, text: str | None
    ) -> None:
        """Keep the member list in step with ``actions`` and send them to their sockets."""
        out: list[tuple[str, Action]] = []
        closed: list[str] = []
        for action in actions:
            conn = owned.global_ids.get(action.conn)
            if conn is None:
                continue
            out.append((conn, action))
            if isinstance(action, Close):
                closed.append(conn)
            elif action.message.get("type") == "login" and action.message.get("success"):
                # Only the sender's own login succeeds in a batch: ``text`` is that login.
                login = parse(text or "")
                if conn == sender and isinstance(login, Login):
                    self._joined(owned, conn, login)
            elif action.message.get("type") == "renewed" and conn in owned.entries:
                self._renewed(owned, conn)
        for conn in closed:
            owned.forget(conn)  # the hub has already taken it out of the room
            self._left(owned, conn)
        # A sender not logged in after its frame (refused login, "log in first") is not kept:
        # its socket is back in its lobby.
        if sender is not None and sender not in owned.members and sender in owned.hub_ids:
            owned.forget(sender)
        self._send(out)
        if owned.name in self._owned and not owned.hub.rooms():
            self._release_room(owned)

    def _joined(self, owned: _Room, conn: str, login: Login) -> None:
        owned.members.add(conn)
        # What a replay needs: the token was checked now, so it is not stored; what it grants
        # is, for the session to end when it expires.
        entry = {
            "seq": owned.seq,
            "login": {"type": "login", "name": login.name, "role": login.role, "room": login.room},
            "claims": self._claims_of(owned, conn),
        }
        owned.seq += 1
        owned.entries[conn] = entry
        self._outbound.put_nowait(("member", (owned.name, conn, json.dumps(entry))))

    def _renewed(self, owned: _Room, conn: str) -> None:
        """``conn`` renewed its token: its entry holds the claims of the new one."""
        entry = {**owned.entries[conn], "claims": self._claims_of(owned, conn)}
        owned.entries[conn] = entry
        self._outbound.put_nowait(("member", (owned.name, conn, json.dumps(entry))))

    @staticmethod
    def _claims_of(owned: _Room, conn: str) -> dict[str, Any] | None:
        claims = owned.hub.claims_of(owned.hub_ids[conn])
        return None if claims is None else asdict(claims)

    def _left(self, owned: _Room, conn: str) -> None:
        owned.members.discard(conn)
        self._outbound.put_nowait(("unmember", (owned.name, conn)))

    def _send(self, out: list[tuple[str, Action]]) -> None:
        """Route each action to the instance holding its socket, in order."""
        batches: dict[str, list[dict[str, Any]]] = {}
        for conn, action in out:
            instance, local = conn.split("/", 1)
            match action:
                case Outgoing(message=message):
                    item: dict[str, Any] = {"conn": local, "message": message}
                case Close(code=code, reason=reason):
                    item = {"conn": local, "close": [code, reason]}
            batches.setdefault(instance, []).append(item)
        for instance, items in batches.items():
            if instance == self.id:
                self._deliver_local(items)
            else:
                self._outbound.put_nowait(("deliver", (instance, items)))

    def _release_room(self, owned: _Room) -> None:
        del self._owned[owned.name]
        self._releasing.add(owned.name)
        self._outbound.put_nowait(("release", owned.name))

    async def _drop_dead_members(self, rooms: list[_Room]) -> None:
        """Disconnect the members whose instance has stopped renewing its heartbeat."""
        members = [(owned, conn) for owned in rooms for conn in sorted(owned.members)]
        others = sorted({conn.split("/", 1)[0] for _, conn in members} - {self.id})
        alive = {self.id}
        if others:
            found = await self.redis.exists(*[keys.instance(i) for i in others])
            if found != len(others):  # someone is gone: find out who
                async with self.redis.pipeline(transaction=False) as pipe:
                    for instance in others:
                        pipe.exists(keys.instance(instance))
                    answers = await pipe.execute()
                alive |= {i for i, answer in zip(others, answers, strict=True) if answer}
            else:
                alive |= set(others)
        for owned, conn in members:
            instance, local = conn.split("/", 1)
            gone = instance not in alive or (instance == self.id and local not in self._locals)
            if gone and self._owned.get(owned.name) is owned and conn in owned.members:
                log.info("member %s of room %r is gone with its instance", conn, owned.name)
                self._remove_member(owned, conn)

    # -- socket side: deliveries from owners ---------------------------------------------------

    def _deliver_local(self, items: list[dict[str, Any]]) -> None:
        actions: list[Action] = []
        for item in items:
            local = self._locals.get(item["conn"])
            if local is None:
                continue  # the socket closed meanwhile
            if "close" in item:
                code, reason = item["close"]
                local.closing = True
                actions.append(Close(local.id, code, reason))
                continue
            message = item["message"]
            if message.get("type") == "login":
                local.logged_in = bool(message.get("success"))
                if not local.logged_in:
                    local.room = None  # refused: the socket is back in the lobby
            actions.append(Outgoing(local.id, message))
        self.deliver(actions)

    async def _listen(self, pubsub: PubSub) -> None:
        """Everything sent to this instance: frames for rooms it owns, deliveries to its sockets."""
        async for message in pubsub.listen():
            if message["type"] != "message":
                continue
            try:
                data = json.loads(message["data"])
                if data["op"] == "room":
                    owned = self._owned.get(data["room"])
                    if owned is not None:
                        self._on_room_op(owned, data)
                    else:  # released or never ours: find the owner again
                        task = asyncio.create_task(self._forward(data))
                        self._forwarding.add(task)
                        task.add_done_callback(self._forwarding.discard)
                elif data["op"] == "deliver":
                    self._deliver_local(data["items"])
            except (KeyError, ValueError, TypeError) as exc:
                log.error("bad fleet message %.200r: %s", message["data"], exc)

    async def _publish(self) -> None:
        """Send the owner's deliveries and member-list changes, in the order they were made.

        Whatever has queued up meanwhile goes in one pipeline: one round trip for a burst, where
        one command at a time made a busy owner's deliveries wait in line behind each other.
        """
        while True:
            batch = [await self._outbound.get()]
            while not self._outbound.empty() and len(batch) < PUBLISH_BATCH:
                batch.append(self._outbound.get_nowait())
            try:
                async with self.redis.pipeline(transaction=False) as pipe:
                    for kind, payload in batch:
                        await self._queue_command(pipe, kind, payload)
                    await pipe.execute()
            except aioredis.RedisError as exc:
                log.error("fleet publish of %d commands failed: %s", len(batch), exc)

    async def _queue_command(self, pipe: Pipeline, kind: str, payload: Any) -> None:
        if kind == "deliver":
            instance, items = payload
            message = json.dumps({"op": "deliver", "items": items})
            pipe.publish(keys.inbox(instance), message)
        elif kind == "member":
            room, conn, entry = payload
            pipe.hset(keys.room_members(room), conn, entry)
            pipe.pexpire(keys.room_members(room), keys.MEMBERS_TTL_MS)
        elif kind == "unmember":
            room, conn = payload
            pipe.hdel(keys.room_members(room), conn)
        elif kind == "release":
            room = payload
            if room in self._releasing:  # not taken up again meanwhile
                self._releasing.discard(room)
                pipe.delete(keys.room_members(room))
                pipe.srem(keys.ROOMS, room)
                # Queued, not sent: the pipeline sends it with the rest.
                await self._release(keys=[keys.room_owner(room)], args=[self.id], client=pipe)

    async def _watch(self) -> None:
        """Every tick: heartbeat, lease renewal, dead members out, orphaned rooms taken over."""
        while True:
            try:
                await self._tick()
            except aioredis.RedisError as exc:
                log.error("fleet tick failed: %s", exc)
            await asyncio.sleep(keys.TICK_S)

    async def _tick(self) -> None:
        # A constant number of round trips, however many rooms: on a loaded instance a renewal
        # per room could take longer than the lease itself.
        await self.redis.set(keys.instance(self.id), self.id, px=keys.INSTANCE_TTL_MS)
        rooms = list(self._owned)
        if rooms:
            held = await self._renew_many(
                keys=[keys.room_owner(room) for room in rooms], args=[self.id, keys.ROOM_LEASE_MS]
            )
            async with self.redis.pipeline(transaction=False) as pipe:
                for room in rooms:
                    pipe.pexpire(keys.room_members(room), keys.MEMBERS_TTL_MS)
                await pipe.execute()
            for room, kept in zip(rooms, held, strict=True):
                if not kept and room in self._owned:
                    log.warning("lost the lease of room %r; another instance runs it now", room)
                    del self._owned[room]
            await self._drop_dead_members(list(self._owned.values()))
        # Rooms our sockets are in whose owner is gone: claim them (only one instance wins).
        joined = {local.room for local in self._locals.values() if local.room is not None}
        for room in set(self._owners) - joined:
            del self._owners[room]
        orphans = sorted(joined - set(self._owned))
        if orphans:
            owners = await self.redis.mget([keys.room_owner(room) for room in orphans])
            for room, owner in zip(orphans, owners, strict=True):
                if owner is None:
                    await self._claim(room)


def _as_login(text: str, max_bytes: int) -> Login | None:
    """``text`` as a valid ``login`` within the size limit, else None (the lobby answers it)."""
    if len(text.encode("utf-8")) > max_bytes:
        return None
    message = parse(text)
    if isinstance(message, ParseError) or not isinstance(message, Login):
        return None
    return message


def _text(value: bytes | str | None) -> str | None:
    """A Redis reply as text (the client decodes replies; bytes only appear in its types)."""
    return value.decode() if isinstance(value, bytes) else value
