"""``autopilot bench --relay-cost``: where one relayed room's cores go.

One room, default profile, the Python agent sending its synthetic 640x480 video at ``--fps``
(30): the relay page runs in a Chromium of its own (the client page in another), so that every
process and thread of that Chromium is the relay's. The relay forwards the video as it does
(passed through where its Chromium can); with ``--baseline`` the same room is measured again
with the relay's encoded transforms removed (:data:`NO_ENCODED_TRANSFORMS`: the fallback that
decodes and encodes for each client), the two forwards in alternation, so that a machine whose
speed drifts between runs biases neither. Over the measured window:

- **threads**: each thread's CPU time from ``/proc/<pid>/task/<tid>/stat``, over the relay
  Chromium's process tree, divided by the window (cores);
- **Chromium's codec counters**: ``getStats()`` ``totalDecodeTime`` of the vehicle's video and
  ``totalEncodeTime`` of the forward to the client (read through a probe script that keeps the
  page's ``RTCPeerConnection``\\ s; the page itself exposes none);
- **the worker's own timers**: per snapshot, the pixel copy and conversion (``workMs - ms``)
  and the cascade (``ms``), from the page's ``autopilotStatus``;
- **the page's main thread**: CDP ``Performance.getMetrics`` (task and script time);
- **the client's glass to glass**: vehicle capture to presentation at the client page, from its
  ``window.autopilotHealth``, and how the relay forwarded (``autopilotStatus.forwards``).

:func:`breakdown` turns these into stages; ``relay-cost.md`` (and ``.json``) shows both the
stages and the busiest threads, so the attribution can be checked.
"""

from __future__ import annotations

import json
import os
import statistics
import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from playwright.async_api import Browser, CDPSession, Page

from app.protocol.opencv import OpenCvBuild
from app.tools.bench.cpu import PROC, ThreadCpu, thread_cpu
from app.tools.bench.stack import StackError, StackOptions, run_profile, set_operation
from app.tools.bench.stats import Summary, summarize

# On the relay's Chromium alone (Chromium hands no unknown switch to its children, and ignores
# it): finds that browser's main process in /proc.
MARKER = "--autopilot-bench-relay-cost"

# Run before the relay page's scripts: a browser without encoded transforms, whose relay
# decodes the vehicle's video and encodes it again for each client (net/relay-links.js).
NO_ENCODED_TRANSFORMS = "delete window.RTCRtpScriptTransform;"
# The relay's cores per room that forwarding without re-encoding is to reach, at
# the vehicle's usual frame rate.
TARGET_CORES_PER_ROOM = 0.18
TARGET_FPS = 30
# Another operation's room may cost the relay at most this many times the cores of a room that
# runs the default face cascade (REFERENCE_OP) on the same build, with the same forward.
REFERENCE_OP = "face"
TARGET_OVER_REFERENCE = 1.5
# The forwards ``--baseline`` alternates: as the relay does it, and the fallback.
FORWARDS = {"as is": "", "re-encode": NO_ENCODED_TRANSFORMS}

# Keeps every RTCPeerConnection the relay page makes, for getStats() (runs before its scripts).
PROBE = """(() => {
  const Native = window.RTCPeerConnection;
  const kept = [];
  window.__benchPeerConnections = kept;
  window.RTCPeerConnection = function RTCPeerConnection(...args) {
    const pc = new Native(...args);
    kept.push(pc);
    return pc;
  };
  window.RTCPeerConnection.prototype = Native.prototype;
})();"""

# Codec counters summed over the relay's connections: the vehicle's video in, the forwards out.
_CODEC_JS = """async () => {
  const out = { decodeS: 0, decoded: 0, encodeS: 0, encoded: 0, sent: [] };
  for (const pc of window.__benchPeerConnections ?? []) {
    (await pc.getStats()).forEach((s) => {
      if (s.kind !== 'video') return;
      if (s.type === 'inbound-rtp') {
        out.decodeS += s.totalDecodeTime ?? 0;
        out.decoded += s.framesDecoded ?? 0;
      } else if (s.type === 'outbound-rtp') {
        out.encodeS += s.totalEncodeTime ?? 0;
        out.encoded += s.framesEncoded ?? 0;
        out.sent.push({ width: s.frameWidth ?? null, height: s.frameHeight ?? null,
          bytesSent: s.bytesSent ?? 0 });
      }
    });
  }
  return out;
}"""

# The worker's per-snapshot timers since snapshot `seen` (the page keeps bounded rings).
_TIMERS_JS = """(seen) => {
  const s = window.autopilotStatus;
  const k = Math.min(s.snapshots - seen, s.workMs.length);
  return { snapshots: s.snapshots, work: k > 0 ? s.workMs.slice(-k) : [],
    detect: k > 0 ? s.detectMs.slice(-k) : [] };
}"""

STAGES = (
    "vision worker: pixel copy and RGBA conversion",
    "vision worker: detection (cascade or DNN)",
    "video encode (forward to the client)",
    "video decode (vehicle's video)",
    "page main thread (JS, frame reading, DOM)",
    "drawing the page and its video (compositors, GPU process)",
    "WebRTC transport (RTP, SRTP, sockets)",
    "renderer thread pool, other",
    "browser process and the rest",
    "forward worker (the vehicle's frames passed to the client)",
)


@dataclass(frozen=True)
class Sample:
    """What is read at each end of the window."""

    threads: list[ThreadCpu]
    codec: dict[str, Any]
    main_thread: dict[str, float]
    snapshots: int


def find_marked_browser(marker: str = MARKER) -> int:
    """The pid of the Chromium main process launched with ``marker``."""
    for entry in PROC.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().decode(errors="replace")
        except OSError:
            continue
        if marker in argv.replace("\0", " ").split(" "):
            return int(entry.name)
    raise RuntimeError(f"no process runs with {marker}")


def _stage_of(thread: ThreadCpu) -> str:
    """The stage a thread's time goes to (its codec and worker shares are split later)."""
    if thread.process == "renderer":
        if thread.name.startswith("DedicatedWorker"):
            return "worker"
        if thread.tid == thread.pid:
            return STAGES[4]
        if thread.name.startswith(("Compositor", "VideoFrameCompo")):
            return STAGES[5]
        if thread.name.startswith(("WebRTC", "Chrome_ChildIOT")):
            return STAGES[6]
        if thread.name.startswith("ThreadPool"):
            return "pool"
        return STAGES[8]
    if thread.process == "gpu-process":
        return STAGES[5]
    if thread.process == "utility:network.mojom.NetworkService":
        return STAGES[6]
    return STAGES[8]


def thread_cores(
    before: Sequence[ThreadCpu], after: Sequence[ThreadCpu], seconds: float
) -> list[tuple[ThreadCpu, float]]:
    """Each thread alive at the end with the cores it used over the window, busiest first."""
    start = {(t.pid, t.tid): t.cpu_s for t in before}
    used = [(t, max(0.0, t.cpu_s - start.get((t.pid, t.tid), 0.0)) / seconds) for t in after]
    return sorted(used, key=lambda pair: -pair[1])


def breakdown(
    threads: Sequence[tuple[ThreadCpu, float]],
    encode_cores: float,
    decode_cores: float,
    pixel_share: float,
) -> dict[str, float]:
    """Cores per stage (:data:`STAGES`) and ``total``.

    The vision worker's thread (the busiest worker thread) is split by its own timers
    (``pixel_share``: the pixel copy's part of its time); any other worker thread is the
    pass-through forward's; the renderer's thread pool, where Chromium runs the video codecs, by the
    codec counters (``getStats`` times, which are wall time: a pool that used less CPU than
    they say is all codec, and the rest of the pool shows as 0).
    """
    by_stage = dict.fromkeys((*STAGES, "pool"), 0.0)
    workers = [cores for thread, cores in threads if _stage_of(thread) == "worker"]
    for thread, cores in threads:
        stage = _stage_of(thread)
        if stage != "worker":
            by_stage[stage] += cores
    # Two workers share the thread name: the vision worker, by far the busier, and the
    # pass-through forward's (absent where the relay encodes for the client).
    worker = max(workers, default=0.0)
    by_stage[STAGES[9]] = sum(workers) - worker
    pool = by_stage.pop("pool")
    by_stage[STAGES[0]] = worker * pixel_share
    by_stage[STAGES[1]] = worker * (1 - pixel_share)
    codecs = encode_cores + decode_cores
    # Within the pool, the two codecs in proportion to their own counters.
    in_pool = min(pool, codecs)
    by_stage[STAGES[2]] = in_pool * encode_cores / codecs if codecs else 0.0
    by_stage[STAGES[3]] = in_pool * decode_cores / codecs if codecs else 0.0
    by_stage[STAGES[7]] = pool - in_pool
    found = {stage: round(by_stage[stage], 3) for stage in STAGES}
    found["total"] = round(sum(cores for _, cores in threads), 3)
    return found


async def _main_thread(cdp: CDPSession) -> dict[str, float]:
    metrics = (await cdp.send("Performance.getMetrics"))["metrics"]
    return {m["name"]: float(m["value"]) for m in metrics}


@dataclass(frozen=True)
class Room:
    """What one measured room runs: the relay's operation, its OpenCV.js build and its forward
    (a key of :data:`FORWARDS`)."""

    op: str
    opencv: OpenCvBuild
    forward: str = "as is"


async def run(
    browser: Browser,
    client_browser: Browser,
    server_url: str,
    seconds: float,
    fps: float,
    room: Room,
) -> dict[str, Any]:
    """Measure one room for ``seconds``, its relay running as ``room`` says (the operation set
    from the client once goals flow, as a person would); ``browser`` must have been launched
    with :data:`MARKER` and hold nothing else."""
    root = find_marked_browser()
    state: dict[str, Any] = {}

    async def sample(relay: Page) -> Sample:
        return Sample(
            thread_cpu(root),
            await relay.evaluate(_CODEC_JS),
            await _main_thread(state["cdp"]),
            (await relay.evaluate(_TIMERS_JS, 0))["snapshots"],
        )

    async def prepare(relay: Page, client: Page) -> None:
        loaded = await relay.evaluate("() => window.autopilotStatus.opencvBuild")
        if loaded != room.opencv:
            raise StackError(f"the relay loaded the {loaded} OpenCV.js, not the {room.opencv}")
        if await relay.evaluate("() => window.autopilotStatus.op") != room.op:
            await set_operation(relay, client, room.op)
        state["cdp"] = await relay.context.new_cdp_session(relay)
        await state["cdp"].send("Performance.enable")
        state["before"] = await sample(relay)
        state["t0"] = os.times().elapsed

    async def finish(relay: Page, _client: Page) -> None:
        state["after"] = await sample(relay)
        state["seconds"] = os.times().elapsed - state["t0"]
        state["timers"] = await relay.evaluate(_TIMERS_JS, state["before"].snapshots)
        state["forwards"] = await relay.evaluate("() => window.autopilotStatus.forwards")

    with tempfile.TemporaryDirectory(prefix="autopilot-bench-relay-cost-") as tmp:
        measured = await run_profile(
            browser,
            server_url,
            StackOptions("default", seconds, fps=fps, name="relay-cost", opencv=room.opencv),
            Path(tmp),
            prepare=prepare,
            client_browser=client_browser,
            finish=finish,
            relay_init_script=PROBE + FORWARDS[room.forward],
        )
    found = figures(
        state,
        measured.processing_summary(),
        measured.glass_ms(),
        measured.relay_goals,
        measured.window,
        fps,
    )
    found |= {"op": room.op, "opencv": room.opencv, "forward": state["forwards"].get("client")}
    client_glass = summarize(measured.client_glass)
    found["client_glass_to_glass_ms"] = (
        None
        if client_glass is None
        else {"p50": round(client_glass.p50, 1), "p95": round(client_glass.p95, 1)}
    )
    return found


def figures(
    state: Mapping[str, Any],
    processing: Summary | None,
    glass_ms: list[float],
    goals: int,
    window: tuple[float, float] | None,
    fps: float,
) -> dict[str, Any]:
    """The report's figures from the two samples and the stack run's own."""
    before, after, seconds = state["before"], state["after"], state["seconds"]
    threads = thread_cores(before.threads, after.threads, seconds)
    work, detect = state["timers"]["work"], state["timers"]["detect"]
    pixels = [w - d for w, d in zip(work, detect, strict=True)]
    pixel_share = sum(pixels) / sum(work) if sum(work) > 0 else 0.0
    counters = ("decodeS", "decoded", "encodeS", "encoded")
    codec = {key: after.codec[key] - before.codec[key] for key in counters}
    main = {
        key: (after.main_thread.get(key, 0) - before.main_thread.get(key, 0)) / seconds
        for key in ("TaskDuration", "ScriptDuration")
    }
    glass = summarize(glass_ms)
    return {
        "seconds": round(seconds, 1),
        "fps": fps,
        "relay_cores": breakdown(
            threads, codec["encodeS"] / seconds, codec["decodeS"] / seconds, pixel_share
        ),  # fmt: skip
        "threads": [
            {"process": t.process, "thread": t.name, "cores": round(c, 3)}
            for t, c in threads
            if c >= 0.005
        ],
        "per_snapshot_ms": {
            "pixels_p50": _p50(pixels),
            "detect_p50": _p50(detect),
            "worker_p50": _p50(work),
            "snapshots": len(work),
        },
        "codecs": {
            "decode_ms_per_frame": _per(codec["decodeS"], codec["decoded"]),
            "encode_ms_per_frame": _per(codec["encodeS"], codec["encoded"]),
            "frames_decoded_per_s": round(codec["decoded"] / seconds, 1),
            "frames_encoded_per_s": round(codec["encoded"] / seconds, 1),
            "forward": after.codec["sent"],
        },
        "main_thread_busy": {k: round(v, 3) for k, v in main.items()},
        "processing_ms": None
        if processing is None
        else {"p50": round(processing.p50, 1), "p95": round(processing.p95, 1)},
        "glass_to_command_ms": None
        if glass is None
        else {"p50": round(glass.p50, 1), "p95": round(glass.p95, 1)},
        "goals_per_s": None if window is None else round(goals / (window[1] - window[0]), 1),
        "load_average": round(os.getloadavg()[0], 2),
    }


def _p50(values: list[float]) -> float | None:
    return round(statistics.median(values), 2) if values else None


def _per(seconds: float, frames: float) -> float | None:
    return round(1000 * seconds / frames, 2) if frames else None


def write_report(
    out: Path, runs: Sequence[dict[str, Any]], provenance: Mapping[str, str] | None = None
) -> Path:
    """``relay-cost.md`` and ``relay-cost.json`` in ``out``: the runs side by side, in the order
    they ran (the JSON holds one run's figures, or ``{"runs": [...]}`` for several), each named
    by its operation, OpenCV.js build and forward, under ``provenance``'s date, machine and
    command when given."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "relay-cost.json").write_text(json.dumps(report_object(runs), indent=2) + "\n")
    first = runs[0]
    loads = ", ".join(str(found["load_average"]) for found in runs)
    head = "| stage | " + " | ".join(f"{_label(found)} (cores)" for found in runs) + " |"
    rule = "|---|" + "---:|" * len(runs)
    judged = first["fps"] == TARGET_FPS
    target = f"≤ {TARGET_CORES_PER_ROOM:g} cores per room at {TARGET_FPS} fps"
    lines = [
        "# Where one relayed room's cores go",
        "",
        f"`autopilot bench --relay-cost`: one room, default profile, {first['fps']:g} fps, "
        f"{len(runs)} run(s) of {first['seconds']:g} s in the order shown (load average at "
        f"the end of each: {loads}).",
        "",
    ]
    if provenance:
        lines += [
            f"Run {provenance['started']} on {provenance['machine']}, command "
            f"`{provenance['command']}`.",
            "",
        ]
    lines += [
        f"*Extrapolated*: for a machine too busy to decode and analyse every frame, the vision"
        f" worker's CPU per snapshot analysed times {first['fps']:g}, plus the rest of the"
        f" relay's CPU per frame decoded times {first['fps']:g} (one worker gives at most one"
        " core: above it, frames go unanalysed).",
        "",
        f"Target: the relay's Chromium in all {target}"
        + ("." if judged else f" (not judged: this run's {first['fps']:g} fps)."),
        "",
        head,
        rule,
        *(
            _row(stage, [f"{found['relay_cores'][stage]:.3f}" for found in runs])
            for stage in STAGES
        ),
        _row(
            "**the relay's Chromium in all**",
            [f"**{found['relay_cores']['total']:.3f}**" for found in runs],
        ),
    ]
    if judged:
        totals = [found["relay_cores"]["total"] for found in runs]
        within = ["yes" if total <= TARGET_CORES_PER_ROOM else "no" for total in totals]
        lines.append(_row(f"within {target}", within))
    lines.append(
        _row(
            f"extrapolated to every frame at {first['fps']:g} fps",
            [_cores(_extrapolated(found)) for found in runs],
        )
    )
    over = [over_reference(found, runs) for found in runs]
    if any(ratio is not None for ratio in over):
        over_every = [over_reference(found, runs, _extrapolated) for found in runs]
        same = f"÷ {REFERENCE_OP}'s (same build and forward, mean of its runs)"
        lines += [
            _row(f"{same}, measured", [_times(ratio) for ratio in over]),
            _row(f"{same}, extrapolated", [_times(ratio) for ratio in over_every]),
        ]
        if judged:
            lines.append(
                _row(
                    f"within ≤ {TARGET_OVER_REFERENCE:g}× {REFERENCE_OP}'s cores, measured",
                    [_within(ratio) for ratio in over],
                )
            )
    lines += [
        "",
        "| figure | " + " | ".join(_label(found) for found in runs) + " |",
        rule,
    ]
    figures_of = [_figure_rows(found) for found in runs]
    lines += [_row(name, [rows[name] for rows in figures_of]) for name in figures_of[0]]
    for found in runs:
        lines += ["", f"Busiest threads, {_label(found)} (cores):", ""]
        lines += ["| process | thread | cores |", "|---|---|---:|"]
        lines += [f"| {t['process']} | {t['thread']} | {t['cores']} |" for t in found["threads"]]
    path = out / "relay-cost.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def over_reference(
    found: Mapping[str, Any],
    runs: Sequence[Mapping[str, Any]],
    cores: Callable[[Mapping[str, Any]], float | None] = lambda run: run["relay_cores"]["total"],
) -> float | None:
    """``found``'s ``cores`` (by default as measured) over the mean of the :data:`REFERENCE_OP`
    runs' on the same build with the same forward; None when none ran."""
    mine = cores(found)
    same = [
        cores(other)
        for other in runs
        if other["op"] == REFERENCE_OP
        and (other["opencv"], other["forward"]) == (found["opencv"], found["forward"])
    ]
    known = [value for value in same if value is not None]
    if mine is None or not known or statistics.fmean(known) <= 0:
        return None
    return float(mine / statistics.fmean(known))


def _extrapolated(found: Mapping[str, Any]) -> float | None:
    at_every = at_every_frame(found)
    return None if at_every is None else at_every["total"]


def _times(ratio: float | None) -> str:
    return "–" if ratio is None else f"{ratio:.2f}×"


def _cores(cores: float | None) -> str:
    return "–" if cores is None else f"{cores:.3f}"


def _within(ratio: float | None) -> str:
    if ratio is None:
        return "–"
    return "yes" if ratio <= TARGET_OVER_REFERENCE else "no"


def at_every_frame(found: Mapping[str, Any]) -> dict[str, float] | None:
    """What the room would cost with every frame of ``fps`` decoded and analysed, from a run on
    a machine too busy to deliver them: the vision worker's cores per snapshot analysed times
    ``fps``, and the rest of the relay's per frame decoded times ``fps``; with the worker's CPU
    per snapshot (ms). None when the run analysed or decoded nothing."""
    cores, fps = found["relay_cores"], found["fps"]
    snapshots_per_s = found["per_snapshot_ms"]["snapshots"] / found["seconds"]
    decoded_per_s = found["codecs"]["frames_decoded_per_s"]
    if snapshots_per_s <= 0 or decoded_per_s <= 0:
        return None
    worker = cores[STAGES[0]] + cores[STAGES[1]]
    return {
        "worker_cpu_ms_per_snapshot": round(1000 * worker / snapshots_per_s, 2),
        "total": round(worker * fps / snapshots_per_s + (cores["total"] - worker) * fps
                       / decoded_per_s, 3),
    }  # fmt: skip


def _label(found: Mapping[str, Any]) -> str:
    return f"{found['op']} ({found['opencv']}), {found['forward']}"


def report_object(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """What ``--json`` prints and ``relay-cost.json`` holds."""
    return dict(runs[0]) if len(runs) == 1 else {"runs": list(runs)}


def _figure_rows(found: dict[str, Any]) -> dict[str, str]:
    snap, codecs = found["per_snapshot_ms"], found["codecs"]
    return {
        "worker per snapshot, p50: pixels / detect / both (ms)":
            f"{snap['pixels_p50']} / {snap['detect_p50']} / {snap['worker_p50']}"
            f" ({snap['snapshots']} snapshots)",
        "decode, encode per frame (ms, getStats)":
            f"{codecs['decode_ms_per_frame']}, {codecs['encode_ms_per_frame']}",
        "frames decoded, encoded per s":
            f"{codecs['frames_decoded_per_s']}, {codecs['frames_encoded_per_s']}",
        "forward to the client (size encoded; none when passed through)": ", ".join(
            f"{s['width']}x{s['height']}" if s["width"] else "–" for s in codecs["forward"]),
        "main thread busy (task, script; s per s, CDP)":
            f"{found['main_thread_busy']['TaskDuration']}, "
            f"{found['main_thread_busy']['ScriptDuration']}",
        "snapshot → goal p50 / p95 (ms)": _pair(found["processing_ms"]),
        "glass-to-command p50 / p95 (ms)": _pair(found["glass_to_command_ms"]),
        "client glass-to-glass p50 / p95 (ms)": _pair(found["client_glass_to_glass_ms"]),
        "goals per second": str(found["goals_per_s"]),
        "snapshots analysed per second": str(round(snap["snapshots"] / found["seconds"], 1)),
        "vision worker's CPU per snapshot analysed (ms)": str(
            (at_every_frame(found) or {}).get("worker_cpu_ms_per_snapshot", "–")),
    }  # fmt: skip


def _row(name: str, cells: Sequence[str]) -> str:
    return f"| {name} | " + " | ".join(cells) + " |"


def _pair(found: dict[str, float] | None) -> str:
    return "–" if found is None else f"{found['p50']} / {found['p95']}"
