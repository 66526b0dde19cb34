"""``autopilot bench --recorder``: what the flight recorder costs the vehicle.

The default-profile stack runs on the same browser and server as it is ("plain") and with the agent
recording (``--record``, the recorder's defaults: 5 JPEG images a second at quality 80), in
alternating rounds, ``ROUNDS`` unless asked otherwise (plain, recording, plain, recording), each run
the seconds asked for over the rounds: a machine's speed drifts within the hour, and one run after
the other would put all of the drift into the difference. Per mode: the agent process's cores over
the measured windows (its CPU time from /proc / the window, averaged over the rounds), and the
vehicle's share of the latency (goal received → its Twist) and the whole glass-to-command, from the
agent's own event log. Targets: at most 5 % more agent CPU, and no change in glass-to-command beyond
the run-to-run noise (the report shows both modes' p50 and p95 side by side, and each round's
increase).

The difference stays as noisy as the machine, so the recording runs also read the recorder's
own CPU time from the agent's event log (its ``recorder`` event, written when it stops): the
recorder's cores over its runs, and their share of the agent's.
"""

from __future__ import annotations

import json
import statistics
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from playwright.async_api import Browser

from app.protocol.events import RecorderTotals, of_kind
from app.recording import read_event_log
from app.tools.bench.stack import StackError, StackOptions, run_profile
from app.tools.bench.stats import summarize

MAX_CPU_INCREASE_PCT = 5.0
RUNS = ("plain", "recording")
ROUNDS = 2


@dataclass
class _Mode:
    """One mode's runs so far: the agent's cores per run and the latency samples of all."""

    cores: list[float] = field(default_factory=list)
    glass_ms: list[float] = field(default_factory=list)
    goal_ms: list[float] = field(default_factory=list)
    events: list[Path] = field(default_factory=list)


async def run(
    browser: Browser, server_url: str, seconds: float, fps: float, rounds: int = ROUNDS
) -> dict[str, Any]:
    """Both modes' figures over ``rounds`` alternating rounds (``seconds`` of each mode in all),
    each round's and the overall CPU increase, and reasons for anything not measured."""
    figures: dict[str, Any] = {
        "seconds": seconds,
        "fps": fps,
        "round_count": rounds,
        "rounds": [],
        "problems": {},
    }
    modes = {name: _Mode() for name in RUNS}
    with tempfile.TemporaryDirectory(prefix="autopilot-bench-recorder-") as tmp:
        folder = Path(tmp) / "recording"
        for round_no in range(1, rounds + 1):
            cores: dict[str, float] = {}
            for name in RUNS:
                recorded = name == "recording"
                extra = ("--record", str(folder)) if recorded else ()
                options = StackOptions(
                    "default",
                    seconds / rounds,
                    fps=fps,
                    name=f"{name}-{round_no}",
                    agent_args=extra,
                )
                try:
                    measured = await run_profile(browser, server_url, options, Path(tmp))
                except StackError as exc:
                    figures["problems"][f"{name} {round_no}"] = str(exc)
                    continue
                mode = modes[name]
                if measured.agent_cores is not None:
                    cores[name] = measured.agent_cores
                    mode.cores.append(measured.agent_cores)
                mode.glass_ms += measured.glass_ms()
                mode.goal_ms += measured.goal_to_command_ms()
                mode.events.append(Path(tmp) / f"events-{options.name}.jsonl")
            if len(cores) == len(RUNS):
                off, on = cores["plain"], cores["recording"]
                figures["rounds"].append(
                    {
                        "plain_cores": round(off, 4),
                        "recording_cores": round(on, 4),
                        "increase_pct": _increase_pct(off, on),
                    }
                )
        means: dict[str, float] = {}  # each mode's cores, unrounded: the increase comes from them
        for name, mode in modes.items():
            if not mode.events:
                continue
            agent = statistics.fmean(mode.cores) if mode.cores else None
            if agent is not None:
                means[name] = agent
            figures[name] = {
                "agent_cores": None if agent is None else round(agent, 4),
                "glass_to_command_ms": _rounded(mode.glass_ms),
                "goal_to_command_ms": _rounded(mode.goal_ms),
            }
            if name == "recording":
                files = sorted(folder.glob("*.mcap"))
                figures[name]["mcap_bytes"] = sum(f.stat().st_size for f in files)
                figures[name] |= _recorder_share(mode.events, agent)
    if means.get("plain") and "recording" in means:
        figures["agent_cpu_increase_pct"] = _increase_pct(means["plain"], means["recording"])
    return figures


def _increase_pct(plain_cores: float, recording_cores: float) -> float:
    """How much more CPU the agent used recording, in percent of its plain runs' (one decimal)."""
    return round(100 * (recording_cores / plain_cores - 1), 1)


def _recorder_share(events_paths: list[Path], agent_cores: float | None) -> dict[str, Any]:
    """The recorder's own cores (its CPU seconds over its seconds, from the ``recorder`` event
    each recording agent logs when it stops, over all of them) and their share of the agent's;
    empty without the events."""
    runs: list[RecorderTotals] = []
    for path in events_paths:
        runs += of_kind(read_event_log(path), RecorderTotals)
    seconds = sum(totals.seconds for totals in runs)
    if not runs or seconds <= 0:
        return {}
    cores = sum(totals.cpu_s for totals in runs) / seconds
    frames = sum(totals.frames for totals in runs)
    found: dict[str, Any] = {
        "recorder_cores": round(cores, 4),
        "recorder_writer_cores": round(sum(t.writer_cpu_s for t in runs) / seconds, 4),
        "recorder_images": sum(totals.images for totals in runs),
        "recorder_frames_held_pct": round(
            100 * sum(totals.frames_held for totals in runs) / max(frames, 1)
        ),
    }
    if agent_cores:
        found["recorder_share_pct"] = round(100 * cores / agent_cores, 1)
    return found


def _rounded(values: list[float]) -> dict[str, float] | None:
    found = summarize(values)
    return None if found is None else {"p50": round(found.p50, 1), "p95": round(found.p95, 1)}


def write_report(out: Path, figures: dict[str, Any]) -> Path:
    """``recorder.md`` (and ``recorder.json``) in ``out``: the two runs side by side."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "recorder.json").write_text(json.dumps(figures, indent=2) + "\n")
    lines = [
        "# Flight recorder cost",
        "",
        f"Default profile at {figures['fps']:g} fps, the agent without and with `--record` (its "
        f"defaults: 5 JPEG images/s, quality 80), {figures['seconds']:g} s of each in "
        f"{figures['round_count']} alternating rounds.",
        "",
        "| mode | agent cores | glass → command p50 / p95 (ms) | goal → Twist p50 / p95 (ms) |",
        "|---|---|---|---|",
    ]
    for name in RUNS:
        found = figures.get(name)
        if found is None:
            lines.append(f"| {name} | not measured | | |")
            continue
        glass, vehicle = found["glass_to_command_ms"], found["goal_to_command_ms"]
        lines.append(f"| {name} | {found['agent_cores']} | {_pair(glass)} | {_pair(vehicle)} |")
    lines += [f"\nNot measured: {what}: {why}" for what, why in figures["problems"].items()]
    increase = figures.get("agent_cpu_increase_pct")
    rounds = ", ".join(
        f"{r['plain_cores']} → {r['recording_cores']} ({r['increase_pct']:+.1f} %)"
        for r in figures["rounds"]
    )
    lines += [
        "",
        f"Agent CPU with recording: {'not measured' if increase is None else f'{increase:+.1f} %'}"
        f" (target ≤ +{MAX_CPU_INCREASE_PCT:g} %); round by round, agent cores: {rounds or '–'}.",
    ]
    recording = figures.get("recording", {})
    share = recording.get("recorder_share_pct")
    if share is not None:
        lines.append(
            f"The recorder's own CPU (its loop work and writer thread, from the agent's event "
            f"log): {recording['recorder_cores']} cores, {share:.1f} % of the recording agent's "
            f"(writer thread {recording['recorder_writer_cores']}; {recording['recorder_images']} "
            f"images; {recording['recorder_frames_held_pct']} % of the camera's frames held)."
        )
    if "mcap_bytes" in recording:
        size = recording["mcap_bytes"] / 1e6
        lines.append(f"Recorded: {size:.1f} MB (the whole run, set-up included).")
    path = out / "recorder.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _pair(found: dict[str, float] | None) -> str:
    return "–" if found is None else f"{found['p50']} / {found['p95']}"
