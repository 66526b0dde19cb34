"""``override_ms_p50`` / ``override_ms_p95`` and ``deadman_stop_s``: the operator's console
(docs/architecture.md, "Who holds the wheel").

The stack runs under the default profile with the agent as the vehicle; once goals flow the
client page takes the wheel and the bench presses ArrowLeft as a person would, ``TRIALS`` times
(or as many as ``autopilot bench --presses`` asks).
Override latency: the moment the bench hands the key event to the client page → the agent's
first manual Twist after it (its ``twist`` event, published to the turtle's ``cmd_vel``); both
on this machine's monotonic clock. Dead-man: with the key held, the client page's script is
paused (a frozen or cut-off operator: no more commands, no key release); the figure is the
agent's last applied drive command → its zero Twist.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.protocol.control import DEADMAN_S
from app.protocol.events import AnyEvent, DriveReceived, TwistSent, of_kind
from app.recording import read_event_log
from app.tools.bench.results import ProfileRun, Target
from app.tools.bench.stack import StackError, StackOptions, run_profile, wait_for
from app.tools.bench.stats import summarize

if TYPE_CHECKING:
    from playwright.async_api import Page

P50, P95, DEADMAN = "override_ms_p50", "override_ms_p95", "deadman_stop_s"
TARGETS = (
    Target(P50, 50.0, True, "key event -> its Twist p50 <= 50 ms"),
    Target(DEADMAN, 0.35, True, "last drive command -> zero Twist <= 0.35 s"),
)
TRIALS = 12
HOLD_S = 0.3  # each press is held this long; the next comes PERIOD_S after it
PERIOD_S = 1.0  # a press's Twist is the first manual one within this long (a loaded machine)
SILENT_S = 1.0  # the paused client page stays silent this long: the dead-man fires inside it
GRANTED_TIMEOUT_S = 15.0


async def run(
    browser: Any, server_url: str, fps: float, workdir: Path, trials: int | None = None
) -> tuple[ProfileRun, list[float], Path]:
    """Bring the stack up, take the wheel, press the keys (``trials`` times, else ``TRIALS``);
    the run, the press times and the agent's event log."""
    presses: list[float] = []

    async def drive(relay: Page, client: Page) -> None:
        await client.get_by_role("button", name="Take Over").click()
        await wait_for(
            client,
            "() => window.autopilotStatus.mode?.mode === 'manual'",
            GRANTED_TIMEOUT_S,
            "the relay did not give the client the wheel",
        )
        for _ in range(trials or TRIALS):
            presses.append(time.monotonic())
            await client.keyboard.down("ArrowLeft")
            await asyncio.sleep(HOLD_S)
            await client.keyboard.up("ArrowLeft")
            await asyncio.sleep(PERIOD_S - HOLD_S)
        await client.keyboard.down("ArrowLeft")
        await asyncio.sleep(HOLD_S)
        cdp = await client.context.new_cdp_session(client)
        await cdp.send("Debugger.enable")
        await cdp.send("Debugger.pause")
        await asyncio.sleep(SILENT_S)
        await cdp.send("Debugger.resume")
        await client.keyboard.up("ArrowLeft")
        await client.get_by_role("button", name="Hand Back").click()

    options = StackOptions("default", 1.0, fps=fps, name="override")
    try:
        measured = await run_profile(browser, server_url, options, workdir, prepare=drive)
    except StackError as exc:
        measured = ProfileRun("default", problems={P50: str(exc)})
    return measured, presses, workdir / "events-override.jsonl"


def figures(measured: ProfileRun, presses: list[float], events_path: Path) -> dict[str, Any]:
    """The three figures (None where missing), their reasons and counts."""
    reasons: dict[str, str] = {}
    if P50 in measured.problems:
        reasons = dict.fromkeys((P50, P95, DEADMAN), measured.problems[P50])
        return {"values": dict.fromkeys((P50, P95, DEADMAN)), "reasons": reasons, "details": {}}
    events = read_event_log(events_path)
    manual = [e for e in of_kind(events, TwistSent) if e.seq is None and (e.linear or e.angular)]
    latencies = []
    for pressed in presses:
        first = next((e.t for e in manual if e.t >= pressed), None)
        if first is not None and first - pressed < PERIOD_S:
            latencies.append((first - pressed) * 1000)
    summary = summarize(latencies)
    if summary is None:
        reasons[P50] = reasons[P95] = "no manual Twist followed a key press"
    stop = _deadman_stop_s(events, presses[-1] if presses else None)
    if stop is None:
        reasons[DEADMAN] = "no zero Twist after the client page went silent"
    values = {
        P50: None if summary is None else round(summary.p50, 1),
        P95: None if summary is None else round(summary.p95, 1),
        DEADMAN: None if stop is None else round(stop, 3),
    }
    return {
        "values": values,
        "reasons": reasons,
        "details": {"presses": len(presses), "answered": len(latencies), "deadman_s": DEADMAN_S},
    }


def _deadman_stop_s(events: list[AnyEvent], after: float | None) -> float | None:
    """The last applied drive command → the zero Twist that followed, after the last press
    cycle (the held key whose release never came)."""
    if after is None:
        return None
    last_drive: float | None = None
    for event in events:
        if event.t < after + PERIOD_S:
            continue
        match event:
            case DriveReceived(applied=True, moving=moving, t=t):
                # A stop command (a release arriving late on a loaded machine) stops by itself.
                last_drive = t if moving else None
            case TwistSent(seq=None, linear=0.0, angular=0.0, t=t) if last_drive is not None:
                return t - last_drive
    return None


def merge(obj: dict[str, Any], found: dict[str, Any]) -> None:
    """Add the figures to the results object: at the top level, with their targets, the counts
    under ``details.override`` and reasons under ``unmeasured.override``."""
    obj.update(found["values"])
    for target in TARGETS:
        obj["targets"][target.key] = {
            "limit": target.limit,
            "upper": target.upper,
            "text": target.text,
        }
    obj["details"]["override"] = found["details"]
    obj["unmeasured"]["override"] = found["reasons"]
