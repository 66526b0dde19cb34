"""``autopilot bench --fleet``: the fleet on a real Redis, measured.

- **signaling**: two ``autopilot serve`` processes on one ``redis-server``; rooms of three
  scripted peers (vehicle, relay, client, no media) with the room's peers split across the two
  instances. Each room logs in, trades offer/answer and 10 candidates per peer pair at ~20 ms
  pacing, the client sends start and stop, and everyone leaves. Every relayed message carries
  the sender's send time (one process, one clock): latency is receive - send. The rooms arrive
  at a steady ``ARRIVAL_ROOMS_PER_S`` (``signaling``), then all again within ``BURST_S``
  (``signaling_burst``: a whole fleet reconnecting at once, which saturates this 2-core box).
- **failover.instance_peers_told_s**: rooms with a vehicle on one instance and a client on the
  other; the vehicle's instance is SIGKILLed; time until every client has heard the ``leave``.
- **failover.pool_takeover_s**: a room with a scripted vehicle and client; pool A (its own
  process) serves it; A is SIGKILLed; time until pool B's relay page has joined the room.
  This is the relay's return, not piloting resumed (that needs media; the e2e test checks it).
- **relay_density**: one instance, one relay pool (its own process, one Chromium), rooms added
  one at a time, each with the vehicle agent (its own process, synthetic 640x480 video with a
  moving face at ``DENSITY_FPS``) and a client page that presses Start Piloting. After each
  room is piloting and has settled, every room's goals/s (as the pool publishes it for
  ``/fleet``) is sampled; the first room count where a room falls below ``MIN_GOALS_PER_S``
  ends it. ``rooms_sustained`` is the last count where every room kept the rate.

Writes ``fleet.json``, ``fleet.md`` and ``fleet-latency.png`` under ``--out``.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import functools
import json
import logging
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import uvloop
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed

from app.resources import APP_DIR
from app.supervise import free_port, stop_process
from app.tools.bench.cpu import cores_used, tree_cpu_s
from app.tools.redis_server import redis_server

log = logging.getLogger(__name__)

FULL = {"rooms": 200, "failover_rooms": 20}
QUICK = {"rooms": 200, "failover_rooms": 10}
CANDIDATES = 10
PACING_S = 0.02  # between two candidates of one peer, as a browser trickles them
# Rooms arrive this fast (200 rooms over 20 s): a session lasts about a second, so about a dozen
# negotiate at once, as on a busy service.
ARRIVAL_ROOMS_PER_S = 10.0
# ... and for the burst figure, every room within this long.
BURST_S = 5.0
# Relay density: the goal rate every room must keep, the agents' frame rate, how long a new
# room may take to start piloting, settle, and be sampled, and the most rooms tried.
MIN_GOALS_PER_S = 15.0
DENSITY_FPS = 30
DENSITY_START_S = 120.0
DENSITY_SETTLE_S = 5.0
DENSITY_SAMPLE_S = 10.0
DENSITY_MAX_ROOMS = {"full": 16, "quick": 6}


@contextlib.contextmanager
def serve_instance(redis_url: str, logdir: Path) -> Iterator[tuple[str, subprocess.Popen[bytes]]]:
    """One ``autopilot serve`` process on ``redis_url``; yields its URL and process."""
    port = free_port()
    env = {**os.environ, "AUTOPILOT_REDIS_URL": redis_url, "AUTOPILOT_ENVIRONMENT": "development"}
    env.pop("AUTOPILOT_TOKEN", None)
    logfile = logdir / f"serve-{port}.log"
    with logfile.open("wb") as out:
        process = subprocess.Popen(
            [sys.executable, "-m", "app.cli", "serve", "--port", str(port)],
            cwd=APP_DIR.parent,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    url = f"http://127.0.0.1:{port}"
    try:
        _wait_healthy(url, process, logfile)
        yield url, process
    finally:
        stop_process(process, grace_s=10)


def _wait_healthy(url: str, process: subprocess.Popen[bytes], logfile: Path) -> None:
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and process.poll() is None:
        with contextlib.suppress(OSError):
            with urllib.request.urlopen(f"{url}/healthz", timeout=1) as response:
                if response.status == 200:
                    return
        time.sleep(0.1)
    raise RuntimeError(f"{url} did not start:\n{logfile.read_text()}")


def _ws(url: str) -> str:
    return url.replace("http", "ws", 1) + "/ws"


@dataclass
class Tally:
    """What the scripted peers saw."""

    latencies_ms: list[float] = field(default_factory=list)
    expected: int = 0
    received: int = 0
    errors: list[str] = field(default_factory=list)


class ScriptedPeer:
    """A WebSocket peer that stamps what it sends and times what it receives."""

    def __init__(self, ws: ClientConnection, name: str, tally: Tally) -> None:
        self.ws, self.name, self.tally = ws, name, tally
        self.inbox: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.reader = asyncio.create_task(self._read())

    async def _read(self) -> None:
        with contextlib.suppress(ConnectionClosed):  # the socket closing ends the reader
            async for raw in self.ws:
                message = json.loads(raw)
                if message.get("type") == "error":
                    self.tally.errors.append(f"{self.name}: {message.get('reason')}")
                if "sent_ns" in message:
                    self.tally.received += 1
                    self.tally.latencies_ms.append(
                        (time.perf_counter_ns() - message["sent_ns"]) / 1e6
                    )
                await self.inbox.put(message)

    async def send(self, message: dict[str, Any], relayed: bool = True) -> None:
        if relayed:
            self.tally.expected += 1
            message = {**message, "sent_ns": time.perf_counter_ns()}
        await self.ws.send(json.dumps(message))

    async def login(self, role: str, room: str) -> None:
        """Log in and wait for the reply; a refusal or no reply within 30 s is an error."""
        login = {"type": "login", "name": self.name, "role": role, "room": room}
        await self.ws.send(json.dumps(login))
        try:
            async with asyncio.timeout(30):
                while (reply := await self.inbox.get()).get("type") != "login":
                    pass
        except TimeoutError:
            self.tally.errors.append(f"{self.name}: no login reply in room {room}")
            return
        if not reply.get("success"):
            self.tally.errors.append(f"{self.name}: login refused: {reply.get('reason')}")


async def _room(index: int, ramp_s: float, rooms: int, urls: list[str], tally: Tally) -> None:
    """One room's whole signaling session, its three peers on alternating instances."""
    room = f"bench-{index}"
    await asyncio.sleep(ramp_s * index / rooms)
    async with contextlib.AsyncExitStack() as stack:
        peers = {}
        for offset, role in enumerate(("relay", "vehicle", "client")):
            ws = await stack.enter_async_context(connect(_ws(urls[(index + offset) % 2])))
            peers[role] = ScriptedPeer(ws, role, tally)
            await peers[role].login(role, room)
        relay, vehicle, client = peers["relay"], peers["vehicle"], peers["client"]
        await asyncio.sleep(0.1)  # rosters settle
        for peer in (vehicle, client):
            await peer.send({"type": "offer", "to": "relay", "sdp": "v=0 offer"})
            await relay.send({"type": "answer", "to": peer.name, "sdp": "v=0 answer"})
            for n in range(CANDIDATES):
                candidate = {"candidate": f"candidate:{n} 1 udp 1 10.0.0.1 {5000 + n} typ host"}
                await peer.send({"type": "candidate", "to": "relay", "candidate": candidate})
                await relay.send({"type": "candidate", "to": peer.name, "candidate": candidate})
                await asyncio.sleep(PACING_S)
        await client.send({"type": "start"})
        await asyncio.sleep(0.5)
        await client.send({"type": "stop"})
        await asyncio.sleep(0.5)  # the last messages arrive before anyone leaves
        for peer in (client, vehicle, relay):
            await peer.send({"type": "leave"}, relayed=False)
        for peer in peers.values():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(peer.reader, 5)


async def _session(index: int, ramp_s: float, rooms: int, urls: list[str], tally: Tally) -> None:
    """One room; a connection the server closed is counted as an error, not a crash."""
    try:
        await _room(index, ramp_s, rooms, urls, tally)
    except ConnectionClosed as exc:
        tally.errors.append(f"room {index}: connection closed: {exc}")


async def bench_signaling(
    urls: list[str], rooms: int, ramp_s: float | None = None
) -> dict[str, Any]:
    """Signaling latency and losses across two instances, the rooms arriving over ``ramp_s``
    (default: at ``ARRIVAL_ROOMS_PER_S``)."""
    ramp_s = rooms / ARRIVAL_ROOMS_PER_S if ramp_s is None else ramp_s
    tally = Tally()
    started = time.monotonic()
    await asyncio.gather(*(_session(i, ramp_s, rooms, urls, tally) for i in range(rooms)))
    ordered = sorted(tally.latencies_ms)
    return {
        "rooms": rooms,
        "peers": rooms * 3,
        "arrival_rooms_per_s": round(rooms / ramp_s, 1),
        "messages": tally.received,
        "latency_ms_p50": _percentile(ordered, 50),
        "latency_ms_p99": _percentile(ordered, 99),
        "errors": len(tally.errors),
        "lost": tally.expected - tally.received,
        "duration_s": round(time.monotonic() - started, 1),
        "_latencies": ordered,
        "_error_samples": tally.errors[:5],
    }


def _percentile(ordered: list[float], p: float) -> float | None:
    if not ordered:
        return None
    return round(ordered[min(len(ordered) - 1, int(len(ordered) * p / 100))], 2)


async def bench_instance_failover(redis_url: str, logdir: Path, rooms: int) -> float:
    """Seconds from SIGKILL of one instance until every peer elsewhere heard its peers leave."""
    with (
        serve_instance(redis_url, logdir) as (doomed, process),
        serve_instance(redis_url, logdir) as (survivor, _),
    ):
        async with contextlib.AsyncExitStack() as stack:
            tally = Tally()
            clients = []
            for i in range(rooms):
                # The first login creates (owns) the room: half on the instance that dies.
                order = [("vehicle", doomed), ("client", survivor)]
                for role, url in order if i % 2 else reversed(order):
                    ws = await stack.enter_async_context(connect(_ws(url)))
                    peer = ScriptedPeer(ws, role, tally)
                    await peer.login(role, f"failover-{i}")
                    if role == "client":
                        clients.append(peer)
            await asyncio.sleep(1.0)
            for client in clients:
                while not client.inbox.empty():
                    client.inbox.get_nowait()
            killed = time.monotonic()
            process.send_signal(signal.SIGKILL)

            async def told(client: ScriptedPeer) -> None:
                while (await client.inbox.get()).get("type") != "leave":
                    pass

            await asyncio.wait_for(asyncio.gather(*(told(c) for c in clients)), 30)
            return round(time.monotonic() - killed, 2)


async def bench_pool_takeover(redis_url: str, logdir: Path) -> float:
    """Seconds from SIGKILL of the serving pool until another pool's relay joined the room."""
    from app.relay.pool import start_pool_process

    with serve_instance(redis_url, logdir) as (url, _):
        async with contextlib.AsyncExitStack() as stack:
            tally = Tally()
            vehicle = ScriptedPeer(
                await stack.enter_async_context(connect(_ws(url))), "vehicle", tally
            )
            await vehicle.login("vehicle", "takeover")
            pools = []
            for name in ("a", "b"):
                pools.append(start_pool_process(url, redis_url, logdir / f"pool-{name}.log"))
                if name == "a":
                    await _relay_joined(vehicle, 90)
            try:
                await asyncio.sleep(3)  # pool B is up and leaves the served room alone
                killed = time.monotonic()
                pools[0].send_signal(signal.SIGKILL)
                await _relay_left(vehicle, 30)
                await _relay_joined(vehicle, 60)
                return round(time.monotonic() - killed, 2)
            finally:
                for pool in pools:
                    if pool.poll() is None:
                        pool.terminate()
                        pool.wait(timeout=30)


async def bench_relay_density(redis_url: str, logdir: Path, max_rooms: int) -> dict[str, Any]:
    """Rooms one pool keeps at ``MIN_GOALS_PER_S`` each, and each room's figures per step."""
    import redis.asyncio as aioredis
    from playwright.async_api import async_playwright

    from app.chromium import launch_options
    from app.relay.pool import start_pool_process
    from app.server.fleet import keys

    steps: list[dict[str, Any]] = []
    children: list[subprocess.Popen[bytes]] = []

    def spawn(name: str, argv: list[str]) -> None:
        with (logdir / f"{name}.log").open("wb") as out:
            children.append(
                subprocess.Popen(
                    [sys.executable, *argv],
                    cwd=APP_DIR.parent,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                )
            )

    with serve_instance(redis_url, logdir) as (url, server):
        redis = aioredis.Redis.from_url(redis_url, decode_responses=True)

        def cpu_s() -> dict[str, float]:
            # Later groups get what earlier ones did not: the bench's own tree holds the
            # client pages' Chromium, Redis and the bench itself.
            return tree_cpu_s(
                {
                    "relay": [children[0].pid],
                    "agents": [child.pid for child in children[1:]],
                    "server": [server.pid],
                    "clients_redis_bench": [os.getpid()],
                }
            )

        async def status(room: str) -> dict[str, Any]:
            raw = await redis.get(keys.relay_status(room))
            return json.loads(raw) if raw else {}

        try:
            children.append(start_pool_process(url, redis_url, logdir / "pool.log"))
            async with async_playwright() as pw:
                browser = await pw.chromium.launch(**launch_options())
                for count in range(1, max_rooms + 1):
                    room = f"density-{count}"
                    spawn(
                        f"agent-{count}",
                        [
                            "-m",
                            "vehicle_agent",
                            "--server",
                            url,
                            "--room",
                            room,
                            "--fps",
                            str(DENSITY_FPS),
                        ],
                    )
                    client = await browser.new_page()
                    await client.goto(f"{url}/client?room={room}&name=client&auto=1")
                    if children[0].poll() is not None:
                        raise RuntimeError(f"the relay pool exited; see {logdir}")
                    start = client.locator("button[data-action=start]")
                    await start.click(timeout=DENSITY_START_S * 1000)
                    try:
                        async with asyncio.timeout(DENSITY_START_S):
                            while not (await status(room)).get("goals_per_s"):
                                if children[0].poll() is not None:
                                    raise RuntimeError(f"the relay pool exited; see {logdir}")
                                await asyncio.sleep(0.5)
                    except TimeoutError:
                        steps.append({"rooms": count, "started": False})
                        break
                    await asyncio.sleep(DENSITY_SETTLE_S)
                    rates: dict[str, list[float]] = {
                        f"density-{i}": [] for i in range(1, count + 1)
                    }
                    ms: dict[str, list[float]] = {name: [] for name in rates}
                    cpu_before, sample_start = cpu_s(), time.monotonic()
                    for _ in range(int(DENSITY_SAMPLE_S)):
                        for name in rates:
                            seen = await status(name)
                            rates[name].append(float(seen.get("goals_per_s") or 0.0))
                            if seen.get("ms_per_snapshot") is not None:
                                ms[name].append(float(seen["ms_per_snapshot"]))
                        await asyncio.sleep(1.0)
                    per_room: dict[str, dict[str, Any]] = {
                        name: {
                            "goals_per_s": round(statistics.median(values), 1),
                            "ms_per_snapshot": round(statistics.median(ms[name]), 1)
                            if ms[name]
                            else None,
                        }
                        for name, values in rates.items()
                    }
                    cores = cores_used(cpu_before, cpu_s(), time.monotonic() - sample_start)
                    step: dict[str, Any] = {
                        "rooms": count,
                        "started": True,
                        "per_room": per_room,
                        "cores": cores,
                        "relay_cores_per_room": round(cores["relay"] / count, 2),
                    }
                    steps.append(step)
                    log.info("relay density: %d rooms: %s", count, per_room)
                    if min(r["goals_per_s"] for r in per_room.values()) < MIN_GOALS_PER_S:
                        break
                await browser.close()
        finally:
            for child in reversed(children):
                stop_process(child, grace_s=30)
            await redis.aclose()
    sustained = 0
    for step in steps:
        kept = step["started"] and all(
            r["goals_per_s"] >= MIN_GOALS_PER_S for r in step["per_room"].values()
        )
        if not kept:
            break
        sustained = step["rooms"]
    density: dict[str, Any] = {
        "rooms_sustained": sustained,
        # Each room's figures at the largest count where every room kept the rate.
        "per_room": [
            {"room": name, **figures}
            for step in steps
            if step["rooms"] == sustained
            for name, figures in step["per_room"].items()
        ],
        "min_goals_per_s": MIN_GOALS_PER_S,
        "fps": DENSITY_FPS,
        "max_rooms_tried": max_rooms,
        "cpus": os.cpu_count(),
        "steps": steps,
    }
    density["relay_cores_per_room"] = relay_cores_per_room(density)
    return density


def relay_cores_per_room(density: dict[str, Any]) -> float | None:
    """The relay's cores per room, median over the steps where every room kept its rate."""
    kept = [
        step["relay_cores_per_room"]
        for step in density["steps"]
        if step.get("relay_cores_per_room")
        and all(r["goals_per_s"] >= density["min_goals_per_s"] for r in step["per_room"].values())
    ]
    return statistics.median(kept) if kept else None


async def _relay_joined(peer: ScriptedPeer, timeout: float) -> None:
    async with asyncio.timeout(timeout):
        while True:
            message = await peer.inbox.get()
            if message.get("type") == "peers" and any(
                p["role"] == "relay" for p in message["peers"]
            ):
                return


async def _relay_left(peer: ScriptedPeer, timeout: float) -> None:
    async with asyncio.timeout(timeout):
        while (await peer.inbox.get()).get("type") != "leave":
            pass


async def run_fleet(args: argparse.Namespace) -> dict[str, Any]:
    """Every fleet figure; a figure that could not be measured is None, its reason in notes."""
    plan = QUICK if args.quick else FULL
    notes: dict[str, str] = {}
    obj: dict[str, Any] = {
        "signaling": None,
        "signaling_burst": None,
        "relay_density": None,
        "failover": {},
    }
    with tempfile.TemporaryDirectory() as tmp, redis_server(Path(tmp)) as redis_url:
        logdir = Path(tmp)
        with (
            serve_instance(redis_url, logdir) as (a, _),
            serve_instance(redis_url, logdir) as (b, _),
        ):
            for key, ramp_s in (("signaling", None), ("signaling_burst", BURST_S)):
                try:
                    obj[key] = await bench_signaling([a, b], plan["rooms"], ramp_s)
                except (OSError, TimeoutError) as exc:
                    notes[key] = str(exc)
        measures = {
            "instance_peers_told_s": functools.partial(
                bench_instance_failover, redis_url, logdir, plan["failover_rooms"]
            ),
            "pool_takeover_s": functools.partial(bench_pool_takeover, redis_url, logdir),
        }
        for key, measure in measures.items():
            try:
                obj["failover"][key] = await measure()
            except (OSError, TimeoutError, RuntimeError) as exc:
                obj["failover"][key] = None
                notes[key] = str(exc) or type(exc).__name__
        try:
            obj["relay_density"] = await bench_relay_density(
                redis_url, logdir, DENSITY_MAX_ROOMS["quick" if args.quick else "full"]
            )
        except (OSError, TimeoutError, RuntimeError) as exc:
            notes["relay_density"] = str(exc) or type(exc).__name__
    obj["notes"] = notes
    return obj


def write(out: Path, obj: dict[str, Any]) -> None:
    """fleet.json, fleet.md and the latency plot."""
    out.mkdir(parents=True, exist_ok=True)
    signaling = obj.get("signaling") or {}
    latencies = signaling.pop("_latencies", [])
    burst_latencies = (obj.get("signaling_burst") or {}).pop("_latencies", [])
    (out / "fleet.json").write_text(json.dumps(obj, indent=2) + "\n")
    lines = ["# Fleet benchmark", ""]
    for key, what in (("signaling", "steady arrival"), ("signaling_burst", "burst")):
        if sig := obj.get(key):
            lines += [
                f"Signaling ({what}), 2 instances + Redis, {sig['rooms']} rooms × 3 peers "
                f"arriving at {sig['arrival_rooms_per_s']:g} rooms/s: {sig['messages']} relayed "
                f"messages, p50 {sig['latency_ms_p50']} ms, p99 {sig['latency_ms_p99']} ms, "
                f"{sig['errors']} errors, {sig['lost']} lost.",
                "",
            ]
    failover = obj["failover"]
    lines += [
        f"Instance killed → peers told: {failover.get('instance_peers_told_s')} s.",
        f"Pool killed → another pool's relay in the room: {failover.get('pool_takeover_s')} s.",
        "",
    ]
    density = obj.get("relay_density")
    if density:
        lines += [
            f"Relay density, one pool on {density['cpus']} CPUs shared with everything else: "
            f"{density['rooms_sustained']} rooms kept ≥ {density['min_goals_per_s']:g} goals/s "
            f"each ({density['fps']} fps video).",
            "",
            "| rooms | per room: goals/s (ms per snapshot) | cores busy: relay, agents, "
            "server, client pages + Redis + bench | relay cores per room |",
            "| --- | --- | --- | --- |",
        ]
        for step in density["steps"]:
            cells = ", ".join(
                f"{r['goals_per_s']} ({r['ms_per_snapshot']})"
                for r in step.get("per_room", {}).values()
            )
            cores = ", ".join(f"{v:g}" for v in step.get("cores", {}).values())
            lines.append(
                f"| {step['rooms']} | {cells or 'did not start piloting'} | {cores or '–'} "
                f"| {step.get('relay_cores_per_room', '–')} |"
            )
        lines.append("")
        if per_room := relay_cores_per_room(density):
            lines += [
                f"One room costs the relay pool (its Chromium included) {per_room:g} cores at "
                f"{density['fps']} fps, where every room kept its goal rate: a relay host with "
                f"nothing else on it would hold about {density['cpus'] / per_room:.0f} rooms on "
                f"{density['cpus']} cores (an estimate from the share, not a measurement).",
                "",
            ]
    lines += [f"- {key}: {why}" for key, why in obj["notes"].items()]
    (out / "fleet.md").write_text("\n".join(lines) + "\n")
    if latencies:
        try:
            import matplotlib

            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
        except ModuleNotFoundError:
            log.warning("matplotlib missing: no latency plot")
            return
        fig, ax = plt.subplots(figsize=(6, 3.5))
        # Cumulative, on a log axis: the p99 tail is what the target is about.
        for label, values in (("steady arrival", latencies), ("burst", burst_latencies)):
            if values:
                share = [(i + 1) / len(values) for i in range(len(values))]
                ax.plot(values, share, label=f"{label}, p50 {statistics.median(values):.1f} ms")
        ax.set_xscale("log")
        ax.axhline(0.99, color="grey", linewidth=0.5)
        ax.set_xlabel("cross-instance signaling latency (ms)")
        ax.set_ylabel("share of messages")
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "fleet-latency.png")
        plt.close(fig)


def run(args: argparse.Namespace) -> int:
    """``autopilot bench --fleet``; 0 when every figure it measures was measured."""
    # The bench's own 600 scripted peers share the cores with what they measure: on uvloop (as
    # uvicorn runs the instances) they cost less and queue less, so the latency is the service's.
    with asyncio.Runner(loop_factory=uvloop.new_event_loop) as runner:
        obj = runner.run(run_fleet(args))
    write(args.out, obj)
    if args.json:
        sys.stdout.write(json.dumps(obj, allow_nan=False) + "\n")
    log.info("fleet report in %s", args.out / "fleet.md")
    measured = ("signaling", "signaling_burst", "relay_density")
    missing = [key for key in measured if obj[key] is None] + [
        key for key, value in obj["failover"].items() if value is None
    ]
    return 1 if missing else 0
