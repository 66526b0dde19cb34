"""A seeded fuzz run (issue 9 item 5): over 10,000 frames across ``/ws``, ``/rosbridge`` and the
agent's data-channel handler -- valid messages mutated, random bytes, big numbers, deep nesting,
invalid UTF-8, slow readers. Afterwards the server has logged no traceback, its memory grew by a
bounded amount, and a legitimate login, relay and rosbridge session still work.

The seed is fixed so a failure replays exactly; set ``AUTOPILOT_FUZZ_SEED`` to explore others.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import os
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.frames import Frame, Opcode
from websockets.protocol import State

from app.server.serve import RunningServer
from tests.helpers.agent import Vehicle
from tests.helpers.sockets import Records, StuckClient, login, recv, rosbridge_url

SEED = int(os.environ.get("AUTOPILOT_FUZZ_SEED", "20261122"))
WS_FRAMES = 4000
ROSBRIDGE_FRAMES = 4000
CHANNEL_FRAMES = 2500
# The server runs in this process; everything it may keep (outboxes, strokes, turtles) is
# capped far below this.
MAX_RSS_GROWTH_BYTES = 64 * 1024 * 1024

VALID_SIGNALING: list[dict[str, Any]] = [
    {"type": "login", "name": "fz", "role": "client", "room": "fuzz"},
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
    {"type": "leave"},
]
VALID_ROSBRIDGE: list[dict[str, Any]] = [
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
    {"type": "error", "reason": "x", "ref": "goal"},
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
    url: str, fuzzer: Fuzzer, valid: list[dict[str, Any]], frames: int, prelude: list[str]
) -> int:
    """Send ``frames`` fuzzed frames, reconnecting whenever the server closes the connection
    (abusive, oversize, invalid UTF-8 ...); returns how many connections were used."""
    sent = connections = 0
    while sent < frames:
        try:
            async with connect(url, max_size=None) as ws:
                connections += 1
                reader = asyncio.create_task(drain(ws))
                try:
                    for text in prelude:
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


async def stuck_clients(url: str, count: int, frame: Callable[[], str]) -> None:
    """Clients that send and never read a byte."""
    stuck = [await asyncio.to_thread(StuckClient, url) for _ in range(count)]
    try:
        for _ in range(40):
            for client in stuck:
                await asyncio.to_thread(client.send, frame())
    finally:
        for client in stuck:
            client.close()


async def test_fuzz_ten_thousand_frames_then_everything_still_works(
    server: RunningServer,
    server_log: Records,
) -> None:
    rng = random.Random(SEED)
    fuzzer = Fuzzer(rng)
    # Built first: the agent's imports and video source are not server memory.
    vehicles = [Vehicle("default"), Vehicle("thesis")]
    rss_before = rss_bytes()
    ros = rosbridge_url(server)
    big_services = json.dumps({"op": "call_service", "service": "/rosapi/services", "id": "s"})

    ws_connections, ros_connections, *_ = await asyncio.gather(
        fuzz_endpoint(
            server.ws_url,
            fuzzer,
            VALID_SIGNALING,
            WS_FRAMES,
            [
                json.dumps(
                    {
                        "type": "login",
                        "name": f"fz{rng.randrange(10**6)}",
                        "role": "client",
                        "room": "fz",
                    }
                )
            ],
        ),
        fuzz_endpoint(ros, fuzzer, VALID_ROSBRIDGE, ROSBRIDGE_FRAMES, []),
        stuck_clients(ros, 3, lambda: big_services),
        stuck_clients(server.ws_url, 3, lambda: '{"type": "login", "name": 1}'),
        asyncio.to_thread(fuzz_channel, Fuzzer(random.Random(SEED + 1)), vehicles, CHANNEL_FRAMES),
    )
    assert WS_FRAMES + ROSBRIDGE_FRAMES + CHANNEL_FRAMES >= 10_000
    assert ws_connections >= 1 and ros_connections >= 1

    # Nothing escaped: no traceback, no "Exception in ASGI application".
    assert server_log.tracebacks() == []
    assert not [r for r in server_log.records if "Exception in ASGI" in r.getMessage()]
    growth = rss_bytes() - rss_before
    logging.getLogger(__name__).info(
        "fuzz seed %d: %d frames, %d /ws and %d /rosbridge connections, RSS growth %.1f MiB",
        SEED,
        WS_FRAMES + ROSBRIDGE_FRAMES + CHANNEL_FRAMES,
        ws_connections,
        ros_connections,
        growth / 2**20,
    )
    assert growth < MAX_RSS_GROWTH_BYTES, f"server grew by {growth / 2**20:.0f} MiB"

    # A legitimate session of each kind still works.
    async with (
        connect(server.ws_url) as relay,
        connect(server.ws_url) as vehicle,
        connect(server.ws_url) as client,
    ):
        await login(relay, "r", "relay")
        await login(vehicle, "v", "vehicle")
        await login(client, "c", "client")
        await vehicle.send(json.dumps({"type": "offer", "to": "r", "sdp": "v=0 offer"}))
        await client.send(json.dumps({"type": "start"}))
        seen = [(await recv(relay))["type"] for _ in range(4)]
        assert seen == ["peers", "peers", "offer", "start"]
    async with connect(ros) as ws:
        await ws.send(json.dumps({"op": "call_service", "service": "/reset", "id": "r"}))
        assert (await recv(ws))["result"] is True
        await ws.send(json.dumps({"op": "subscribe", "topic": "/turtle1/pose"}))
        publication = await recv(ws)
        assert publication["op"] == "publish" and publication["topic"] == "/turtle1/pose"
