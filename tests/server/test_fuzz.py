"""Seeded fuzz runs against a server with tokens on (issue 9 item 5, issue 37): frames across
``/ws`` and ``/rosbridge``, the agent's data-channel handler and the relay's ``control`` channel
parser -- valid messages mutated (logins and renewals with tokens, rosbridge ``auth``, drive,
lock, take-over), random bytes, big numbers, deep nesting, invalid UTF-8, slow readers, and
sockets that show no token, more than an address's budget of them.
Afterwards the server has logged no traceback, its memory stayed flat over the second half of
the run, and a legitimate login, relay and rosbridge session still work.

The fast lane's run is a fifth of the full one (``slow``: 10,000 frames across ``/ws`` and
``/rosbridge``). The seed is fixed so a failure replays exactly; set ``AUTOPILOT_FUZZ_SEED`` to
explore others.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import os
import random
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.frames import Frame, Opcode
from websockets.protocol import State

from app.protocol import channels, tokens
from app.protocol.channels import CONTROL_CHANNEL
from app.server.config import Settings
from app.server.serve import RunningServer
from tests.helpers.agent import Vehicle
from tests.helpers.sockets import Records, StuckClient, recv, rosbridge_url

SEED = int(os.environ.get("AUTOPILOT_FUZZ_SEED", "20261122"))
SECRET = "fuzz-test-secret-0123456789"
ROOM = "fz"
# The second half of a run may grow the server by no more than this: what it keeps (outboxes,
# strokes, turtles, sessions) is capped, so after the first half it has what it will have.
MAX_SECOND_HALF_GROWTH_BYTES = 16 * 1024 * 1024


def token(role: tokens.Role, room: str = ROOM) -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=3600)


def valid_signaling() -> list[dict[str, Any]]:
    return [
        {"type": "login", "name": "fz", "role": "client", "room": ROOM, "token": token("client")},
        {"type": "offer", "to": "r", "sdp": "v=0"},
        {"type": "answer", "to": "c", "sdp": "v=0"},
        {
            "type": "candidate",
            "to": "r",
            "candidate": {"candidate": "candidate:1 1 udp 1 1.2.3.4 5 typ host"},
        },
        {"type": "start"},
        {"type": "stop"},
        {"type": "getOps"},
        {"type": "renew"},
        {"type": "renew", "token": token("client")},
        {"type": "leave"},
    ]


def valid_rosbridge() -> list[dict[str, Any]]:
    return [
        {"op": "auth", "token": token("vehicle")},
        {"op": "auth", "mac": token("client")},
        {
            "op": "publish",
            "topic": "/turtle1/cmd_vel",
            "msg": {"linear": {"x": 1.0}, "angular": {"z": 0.5}},
        },
        {
            "op": "subscribe",
            "id": "s",
            "topic": "/turtle1/pose",
            "throttle_rate": 100,
            "queue_length": 2,
        },
        {"op": "unsubscribe", "id": "s", "topic": "/turtle1/pose"},
        {"op": "advertise", "topic": "/turtle1/cmd_vel", "type": "geometry_msgs/Twist"},
        {"op": "call_service", "service": "/spawn", "args": {"x": 1.0, "y": 2.0, "theta": 0.5}},
        {"op": "call_service", "service": "/kill", "args": {"name": "turtle2"}},
        {
            "op": "call_service",
            "service": "/turtle1/teleport_absolute",
            "args": {"x": 1, "y": 1, "theta": 3},
        },
        {
            "op": "call_service",
            "service": "/turtle1/teleport_relative",
            "args": {"linear": 1, "angular": 1},
        },
        {
            "op": "call_service",
            "service": "/turtle1/set_pen",
            "args": {"r": 1, "g": 2, "b": 3, "width": 4},
        },
        {"op": "call_service", "service": "/rosapi/services", "args": {}},
        {
            "op": "call_service",
            "service": "/rosapi/set_param",
            "args": {"name": "/turtlesim:background_r", "value": "7"},
        },
        {"op": "call_service", "service": "/clear", "args": {}},
        {"op": "set_level", "level": "info"},
    ]


VALID_CHANNEL: list[dict[str, Any]] = [
    {
        "type": "goal",
        "seq": 1,
        "op": "face",
        "x": 100,
        "y": 80,
        "w": 320,
        "h": 240,
        "t": 0,
        "frame": 3,
    },
    {"type": "stop"},
    {"type": "mode", "mode": "manual", "operator": "c", "reason": "take over"},
    {"type": "drive", "seq": 1, "linear": 0.5, "angular": -0.25},
    {"type": "mode", "mode": "auto"},
    {"type": "error", "reason": "x", "ref": "goal"},
]
# What a client sends the relay on ``control``: the relay page validates it against the schema
# of these models; here the models themselves take the fuzz.
VALID_CONTROL: list[dict[str, Any]] = [
    {"type": "lock", "x": 120.5, "y": 80},
    {"type": "unlock"},
    {"type": "takeOver"},
    {"type": "drive", "seq": 7, "linear": 1, "angular": 0},
    {"type": "handBack"},
    {"type": "setOp", "op": "face"},
    {"type": "start"},
    {"type": "stopRobot"},
]


class Fuzzer:
    """Makes hostile frames from valid ones, reproducibly."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng

    def value(self) -> str:
        """A JSON value as text, hostile more often than not."""
        r = self.rng
        return r.choice(
            [
                lambda: "NaN",
                lambda: "-Infinity",
                lambda: "1e999",
                lambda: str(r.choice([1, -1]) * r.getrandbits(r.choice([8, 64, 70, 300]))),
                lambda: "9" * r.choice([25, 400, 5000]),
                lambda: repr(r.choice([1.7976931348623157e308, -1e308, 5e-324, 0.0, -0.0])),
                lambda: "[" * (d := r.choice([10, 40, 900, 3000])) + "]" * d,
                lambda: '{"a":' * (d := r.choice([5, 33, 2000])) + "1" + "}" * d,
                lambda: json.dumps(
                    "".join(chr(r.randrange(1, 0x3000)) for _ in range(r.randrange(40)))
                ),
                lambda: json.dumps("x" * r.choice([1, 65, 5000])),
                lambda: r.choice(["null", "true", "false", "{}", "[]", '""']),
                lambda: json.dumps(r.uniform(-1e6, 1e6)),
            ]
        )()

    def mutate(self, message: dict[str, Any]) -> str:
        """A valid message with one field replaced, dropped or added, as JSON text."""
        r = self.rng
        fields = {k: json.dumps(v) for k, v in message.items()}
        key = r.choice([*fields, "extra", "from", "id"])
        action = r.random()
        if action < 0.15 and key in fields:
            del fields[key]
        else:
            fields[key] = self.value()
        return "{" + ",".join(f"{json.dumps(k)}:{v}" for k, v in fields.items()) + "}"

    def frame(self, valid: list[dict[str, Any]]) -> str | bytes:
        """One frame: mostly mutated messages, also valid ones, garbage text and random bytes."""
        r = self.rng
        roll = r.random()
        if roll < 0.55:
            return self.mutate(r.choice(valid))
        if roll < 0.75:
            return json.dumps(r.choice(valid))
        if roll < 0.85:
            return self.value()
        if roll < 0.95:
            return "".join(chr(r.randrange(32, 127)) for _ in range(r.randrange(1, 60)))
        return r.randbytes(r.randrange(1, 200))  # binary frame


def rss_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS in /proc/self/status")


async def drain(ws: ClientConnection) -> None:
    """Read and drop everything, so the fuzzing client is never the slow reader."""
    with contextlib.suppress(ConnectionClosed):
        async for _ in ws:
            pass


async def fuzz_endpoint(
    url: str,
    fuzzer: Fuzzer,
    valid: list[dict[str, Any]],
    frames: int,
    prelude: Callable[[int], list[str]],
) -> int:
    """Send ``frames`` fuzzed frames, reconnecting whenever the server closes the connection
    (abusive, oversize, invalid UTF-8, a refused token ...); each connection first sends
    ``prelude(n)``; returns how many connections were used."""
    sent = connections = 0
    while sent < frames:
        try:
            # max_queue=None: messages that arrive once ``drain`` is cancelled must not pause the
            # client's reading, or it never reads the server's close and waits 10 s for it.
            async with connect(url, max_size=None, max_queue=None) as ws:
                connections += 1
                reader = asyncio.create_task(drain(ws))
                try:
                    for text in prelude(connections):
                        await ws.send(text)
                    while sent < frames and not reader.done():
                        frame = fuzzer.frame(valid)
                        if fuzzer.rng.random() < 0.01:  # invalid UTF-8 in a text frame
                            if ws.state is not State.OPEN:
                                break
                            ws.protocol.send_frame(Frame(Opcode.TEXT, b'{"op": "\xc3\x28"}'))
                            ws.send_data()
                        else:
                            await ws.send(frame)
                        sent += 1
                        if sent % 50 == 0:
                            await asyncio.sleep(0.005)  # let the server's tick and readers run
                finally:
                    reader.cancel()
                    await asyncio.gather(reader, return_exceptions=True)
        except (ConnectionClosed, InvalidStatus, OSError):
            continue  # the server closed us mid-send: count stands, connect again
    return connections


def fuzz_channel(fuzzer: Fuzzer, vehicles: list[Vehicle], frames: int) -> None:
    """Frames into the agent's real data-channel handler; every pose stays finite."""
    for vehicle in vehicles:
        for n in range(frames // len(vehicles)):
            reply = vehicle.agent.handle_channel_message(fuzzer.frame(VALID_CHANNEL), "relay")
            assert reply is None or (reply.type == "error" and reply.reason)
            if n % 10 == 0:
                vehicle.turtle.sim.step()
        pose = vehicle.turtle.sim.pose("turtle1")
        assert all(math.isfinite(v) for v in (pose.x, pose.y, pose.theta))


def fuzz_control(fuzzer: Fuzzer, frames: int) -> None:
    """Frames through the relay's ``control`` channel models: a message or a refusal, always."""
    for _ in range(frames):
        result = channels.parse(fuzzer.frame(VALID_CONTROL), CONTROL_CHANNEL, "relay")
        if isinstance(result, channels.Refused):
            assert result.reason
        else:
            assert channels.type_of(type(result)) in {m["type"] for m in VALID_CONTROL}


async def stuck_clients(url: str, count: int, first: str, frame: str) -> None:
    """Clients that send ``first``, then ``frame`` again and again, and never read a byte."""
    stuck = [await asyncio.to_thread(StuckClient, url) for _ in range(count)]
    try:
        for client in stuck:
            await asyncio.to_thread(client.send, first)
        for _ in range(40):
            for client in stuck:
                await asyncio.to_thread(client.send, frame)
    finally:
        for client in stuck:
            client.close()


async def unauthenticated_flood(url: str, count: int) -> None:
    """Sockets that show no token: opened one after another from this one address and left
    idle, more than the address's budget of waiting places (the oldest are made to make way)."""

    def flood() -> None:
        opened = []
        try:
            for _ in range(count):
                with contextlib.suppress(OSError, InvalidStatus):
                    opened.append(StuckClient(url))
        finally:
            for client in opened:
                client.close()

    await asyncio.to_thread(flood)


@dataclass(frozen=True)
class Run:
    """How many frames of each kind one half of a run sends."""

    ws: int
    rosbridge: int
    channel: int
    control: int
    # Sockets without a token opened on each of /ws and /rosbridge.
    flood: int


@pytest.fixture
def guarded(start_server: Callable[[Settings], RunningServer]) -> RunningServer:
    return start_server(Settings(environment="development", secret=SECRET))


async def fuzz_half(
    server: RunningServer, rng: random.Random, run: Run, half: int, vehicles: list[Vehicle]
) -> tuple[int, int]:
    """One half of a run; the /ws and /rosbridge connections it used."""
    fuzzer = Fuzzer(rng)
    ros = rosbridge_url(server)
    big_services = json.dumps({"op": "call_service", "service": "/rosapi/services", "id": "s"})

    def ws_prelude(n: int) -> list[str]:
        login = {"type": "login", "name": f"fz{half}-{n}", "role": "client", "room": ROOM}
        return [json.dumps(login | {"token": token("client")})]

    def ros_prelude(n: int) -> list[str]:
        # Readers and drivers in turn: the gate's two paths both take the fuzz.
        return [json.dumps({"op": "auth", "token": token("vehicle" if n % 2 else "client")})]

    ws_connections, ros_connections, *_ = await asyncio.gather(
        fuzz_endpoint(server.ws_url, fuzzer, valid_signaling(), run.ws, ws_prelude),
        fuzz_endpoint(ros, fuzzer, valid_rosbridge(), run.rosbridge, ros_prelude),
        stuck_clients(ros, 3, json.dumps({"op": "auth", "token": token("client")}), big_services),
        stuck_clients(server.ws_url, 3, ws_prelude(0)[0], '{"type": "getOps", "pad": 1}'),
        unauthenticated_flood(server.ws_url, run.flood),
        unauthenticated_flood(ros, run.flood),
        asyncio.to_thread(fuzz_channel, Fuzzer(random.Random(rng.random())), vehicles, run.channel),
        asyncio.to_thread(fuzz_control, Fuzzer(random.Random(rng.random())), run.control),
    )
    return ws_connections, ros_connections


async def fuzz_then_everything_still_works(
    server: RunningServer, server_log: Records, run: Run
) -> None:
    """Two halves of ``run``; memory measured after the first (the server's caches and the
    agents' imports are there by then) and after the second."""
    rng = random.Random(SEED)
    vehicles = [Vehicle("default"), Vehicle("thesis")]  # not server memory: made once
    first = await fuzz_half(server, rng, run, 1, vehicles)
    rss_mid = rss_bytes()
    second = await fuzz_half(server, rng, run, 2, vehicles)
    growth = rss_bytes() - rss_mid

    # Nothing escaped: no traceback, no "Exception in ASGI application".
    assert server_log.tracebacks() == []
    assert not [r for r in server_log.records if "Exception in ASGI" in r.getMessage()]
    logging.getLogger(__name__).info(
        "fuzz seed %d, tokens on: %d /ws and %d /rosbridge frames (%d and %d connections), "
        "%d channel and %d control frames; RSS %.1f MiB after the first half, %+.1f MiB over "
        "the second",
        SEED,
        2 * run.ws,
        2 * run.rosbridge,
        first[0] + second[0],
        first[1] + second[1],
        2 * run.channel,
        2 * run.control,
        rss_mid / 2**20,
        growth / 2**20,
    )
    assert growth < MAX_SECOND_HALF_GROWTH_BYTES, f"grew by {growth / 2**20:.1f} MiB"

    # A legitimate session of each kind still works.
    async with (
        connect(server.ws_url) as relay,
        connect(server.ws_url) as vehicle,
        connect(server.ws_url) as client,
    ):
        peers: list[tuple[ClientConnection, str, tokens.Role]] = [
            (relay, "r", "relay"),
            (vehicle, "v", "vehicle"),
            (client, "c", "client"),
        ]
        for ws, name, role in peers:
            login = {"type": "login", "name": name, "role": role, "room": "after"}
            await ws.send(json.dumps(login | {"token": token(role, "after")}))
            assert (await recv(ws))["success"] is True
        await vehicle.send(json.dumps({"type": "offer", "to": "r", "sdp": "v=0 offer"}))
        await client.send(json.dumps({"type": "start"}))
        seen = [(await recv(relay))["type"] for _ in range(4)]
        assert seen == ["peers", "peers", "offer", "start"]
        await client.send(json.dumps({"type": "renew"}))
        assert (await recv(client))["type"] == "renewed"
    async with connect(rosbridge_url(server)) as ws:
        await ws.send(json.dumps({"op": "auth", "token": token("vehicle")}))
        await ws.send(json.dumps({"op": "call_service", "service": "/reset", "id": "r"}))
        assert (await recv(ws))["result"] is True
        await ws.send(json.dumps({"op": "subscribe", "topic": "/turtle1/pose"}))
        publication = await recv(ws)
        assert publication["op"] == "publish" and publication["topic"] == "/turtle1/pose"


async def test_fuzz_with_tokens_then_everything_still_works(
    guarded: RunningServer, server_log: Records
) -> None:
    await fuzz_then_everything_still_works(guarded, server_log, Run(500, 500, 500, 500, 40))


@pytest.mark.slow
async def test_fuzz_ten_thousand_socket_frames_with_tokens_then_everything_still_works(
    guarded: RunningServer, server_log: Records
) -> None:
    await fuzz_then_everything_still_works(guarded, server_log, Run(2500, 2500, 1250, 1250, 200))
