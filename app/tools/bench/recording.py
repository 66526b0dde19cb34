"""``autopilot bench --recorder``: what the flight recorder costs the vehicle (issue 21).

The default-profile stack runs twice on the same browser and server, first as it is and then
with the agent recording (``--record``, the recorder's defaults: 5 JPEG images a second at
quality 80), each for the same number of seconds. Per run: the agent process's cores over the
measured window (its CPU time from /proc / the window), and the vehicle's share of the latency
(goal received → its Twist) and the whole glass-to-command, from the agent's own event log.
Targets: at most 5 % more agent CPU, and no change in glass-to-command beyond the run-to-run
noise (the report shows both runs' p50 and p95 side by side).

The difference between the two runs is as noisy as the machine (the relay's goal rate, and with
it the agent's work, moves from run to run), so the recording run also reads the recorder's own
CPU time from the agent's event log (its ``recorder`` event, written when it stops): the
recorder's cores over its whole run, and their share of the agent's.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

from playwright.async_api import Browser

from app.tools.bench.stack import StackError, StackOptions, run_profile
from app.tools.bench.stats import summarize
from vehicle_agent.events import Event

MAX_CPU_INCREASE_PCT = 5.0
RUNS = ("plain", "recording")


async def run(browser: Browser, server_url: str, seconds: float, fps: float) -> dict[str, Any]:
    """Both runs' figures, the CPU increase, and reasons for anything not measured."""
    figures: dict[str, Any] = {"seconds": seconds, "fps": fps, "problems": {}}
    with tempfile.TemporaryDirectory(prefix="autopilot-bench-recorder-") as tmp:
        for name in RUNS:
            folder = Path(tmp) / "recording"
            extra = ("--record", str(folder)) if name == "recording" else ()
            options = StackOptions("default", seconds, fps=fps, name=name, agent_args=extra)
            try:
                measured = await run_profile(browser, server_url, options, Path(tmp))
            except StackError as exc:
                figures["problems"][name] = str(exc)
                continue
            cores = measured.agent_cores
            figures[name] = {
                "agent_cores": None if cores is None else round(cores, 4),
                "glass_to_command_ms": _rounded(measured.glass_ms()),
                "goal_to_command_ms": _rounded(measured.goal_to_command_ms()),
            }
            if name == "recording":
                files = sorted(folder.glob("*.mcap"))
                figures[name]["mcap_bytes"] = sum(f.stat().st_size for f in files)
                figures[name] |= _recorder_share(Path(tmp) / f"events-{name}.jsonl", cores)
    plain, recording = figures.get("plain"), figures.get("recording")
    if plain and recording and plain["agent_cores"] and recording["agent_cores"] is not None:
        increase = 100 * (recording["agent_cores"] / plain["agent_cores"] - 1)
        figures["agent_cpu_increase_pct"] = round(increase, 1)
    return figures


def _recorder_share(events_path: Path, agent_cores: float | None) -> dict[str, Any]:
    """The recorder's own cores (its CPU seconds over its seconds, from the ``recorder`` event
    the agent logs when it stops) and their share of the agent's; empty without the event."""
    totals: Event | None = None
    with events_path.open() as lines:
        for line in lines:
            event = json.loads(line)
            if event.get("ev") == "recorder":
                totals = event
    if totals is None or totals["seconds"] <= 0:
        return {}
    cores = totals["cpu_s"] / totals["seconds"]
    found: dict[str, Any] = {
        "recorder_cores": round(cores, 4),
        "recorder_writer_cores": round(totals["writer_cpu_s"] / totals["seconds"], 4),
        "recorder_images": totals["images"],
        "recorder_frames_held_pct": round(100 * totals["frames_held"] / max(totals["frames"], 1)),
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
        f"Default profile, {figures['seconds']:g} s per run at {figures['fps']:g} fps, the agent "
        "without and with `--record` (its defaults: 5 JPEG images/s, quality 80).",
        "",
        "| run | agent cores | glass → command p50 / p95 (ms) | goal → Twist p50 / p95 (ms) |",
        "|---|---|---|---|",
    ]
    for name in RUNS:
        found = figures.get(name)
        if found is None:
            lines.append(f"| {name} | not measured: {figures['problems'].get(name)} | | |")
            continue
        glass, vehicle = found["glass_to_command_ms"], found["goal_to_command_ms"]
        lines.append(f"| {name} | {found['agent_cores']} | {_pair(glass)} | {_pair(vehicle)} |")
    increase = figures.get("agent_cpu_increase_pct")
    lines += [
        "",
        f"Agent CPU with recording: {'not measured' if increase is None else f'{increase:+.1f} %'}"
        f" (target ≤ +{MAX_CPU_INCREASE_PCT:g} %).",
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
