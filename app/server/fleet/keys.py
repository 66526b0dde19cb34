"""Redis key names and the lease timings of the fleet: one place, read by every fleet module.

Every key is under ``autopilot:`` so one Redis can be shared with other software. Liveness is
always a key with a TTL that its holder renews: a holder that dies simply stops renewing.
"""

from __future__ import annotations

PREFIX = "autopilot"

# An instance renews its heartbeat and its room leases every TICK_S; they expire after the TTLs.
# Dead instance -> its peers told: at most INSTANCE_TTL_MS + TICK_S (4 s, target 5 s).
TICK_S = 1.0
INSTANCE_TTL_MS = 3000
ROOM_LEASE_MS = 3000
# A pool renews each relay lease every TICK_S; a dead pool's rooms are free after this.
RELAY_LEASE_MS = 5000
# How long the relay status a pool publishes stays readable without renewal.
RELAY_STATUS_TTL_MS = 5000
# The room's member list outlives its owner's lease so that a new owner can rebuild the room.
MEMBERS_TTL_MS = 60_000

# Channel each instance listens on; every message for it (forwarded frames, deliveries) comes here.
ROOMS = f"{PREFIX}:rooms"  # set of room names that have an owner


def instance(instance_id: str) -> str:
    """Heartbeat key of an instance (value: its id)."""
    return f"{PREFIX}:instance:{instance_id}"


def inbox(instance_id: str) -> str:
    """Pub/sub channel of an instance."""
    return f"{PREFIX}:inbox:{instance_id}"


def room_owner(room: str) -> str:
    """Lease key: the id of the instance that runs this room's hub."""
    return f"{PREFIX}:room:{room}:owner"


def room_members(room: str) -> str:
    """Hash: global connection id -> JSON ``{seq, login}`` of each peer in the room."""
    return f"{PREFIX}:room:{room}:members"


def relay_lease(room: str) -> str:
    """Lease key: the id of the relay pool serving this room."""
    return f"{PREFIX}:relay:{room}"


def relay_status(room: str) -> str:
    """JSON status of the room's pool relay page (piloting, operation, goals/s, ms)."""
    return f"{PREFIX}:relay:{room}:status"


# Lua: renew a lease only if we still hold it (KEYS[1], ARGV[1] = holder, ARGV[2] = ms).
RENEW_LUA = """
if redis.call('get', KEYS[1]) == ARGV[1] then
  return redis.call('pexpire', KEYS[1], ARGV[2])
end
return 0
"""

# Lua: RENEW_LUA for many leases in one call (KEYS = leases); returns 1 or 0 per lease.
RENEW_MANY_LUA = """
local held = {}
for i, key in ipairs(KEYS) do
  if redis.call('get', key) == ARGV[1] then
    redis.call('pexpire', key, ARGV[2])
    held[i] = 1
  else
    held[i] = 0
  end
end
return held
"""

# Lua: delete a lease only if we still hold it (KEYS[1], ARGV[1] = holder).
RELEASE_LUA = """
if redis.call('get', KEYS[1]) == ARGV[1] then
  return redis.call('del', KEYS[1])
end
return 0
"""
