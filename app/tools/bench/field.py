"""``autopilot bench --field``: the real stack in the field lab, once per network condition.

For each condition the lab is set, the whole system is started afresh (NAT and DNAT decisions
are per connection), piloting starts, and after the first goal and a settling second the run
is measured over a window: the agent's event log gives goals, Twists, poses and the link, the
client page its received video frames and its glass to glass (vehicle capture to presentation
at the client, each frame it measured; the lab's namespaces share one clock). ``link_drop``
darkens the robot's link for 3 s inside its window and times the stop and the resumption.
Nothing is asserted here; figures that could not be measured are null with the reason in
``problems``.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.protocol.events import (
    AnyEvent,
    FrameSent,
    GoalApplied,
    LinkChanged,
    PoseReport,
    TwistSent,
    of_kind,
)
from app.protocol.video import VIDEO_SIZE
from app.tools.bench.stats import (
    PoseSample,
    TruthSample,
    glass_to_command_ms,
    heading_error_deg_median,
    heading_track,
)
from vehicle_agent.core.control import pixel_to_terrain

log = logging.getLogger(__name__)

ORDER = ("clean", "turn_only", "loss_2", "loss_10", "rtt_150", "cap_1mbit", "link_drop")
QUICK_WINDOW_S = 15.0
FULL_WINDOW_S = 45.0
FIRST_GOAL_TIMEOUT_S = 120.0
SETTLE_S = 2.0
# link_drop: the outage starts this far into the window.
OUTAGE_AT_S = 4.0
RESUME_TIMEOUT_S = 30.0
# The video rows' keys, in the report's column order.
VIDEO_COLUMNS = (
    "condition", "hint", "degradation_preference", "fps", "width", "kbit_per_s", "limited_by",
)  # fmt: skip
# The client's glass-to-glass samples: how many so far, and the latest (a bounded ring).
_GLASS_JS = """() => ({
  count: window.autopilotHealth.framesTimed,
  ms: window.autopilotHealth.glassToGlassMs,
})"""
_VIDEO_FRAMES_JS = """() => {
  const video = document.querySelector('[data-testid=video]');
  if (!video || !video.getVideoPlaybackQuality) return null;
  return video.getVideoPlaybackQuality().totalVideoFrames;
}"""


@dataclass
class FieldRow:
    """One condition's figures (None: not measured, see ``problems``)."""

    condition: str
    candidate_type: str | None = None
    connect_ms: float | None = None
    glass_to_command_ms_p50: float | None = None
    glass_to_command_ms_p95: float | None = None
    goals_per_s: float | None = None
    heading_error_deg_median: float | None = None
    stale_goals_applied: int | None = None
    client_video_fps: float | None = None
    client_glass_to_glass_ms_p50: float | None = None
    client_glass_to_glass_ms_p95: float | None = None
    problems: dict[str, str] = field(default_factory=dict)

    def client_glass(self, samples: list[float]) -> None:
        """The client's glass-to-glass figures from its samples over the window."""
        if not samples:
            self.problems["client_glass_to_glass_ms_p50"] = (
                "the client measured no frame (no tagged frame with a known capture time)"
            )
            return
        self.client_glass_to_glass_ms_p50 = round(float(np.percentile(samples, 50)), 1)
        self.client_glass_to_glass_ms_p95 = round(float(np.percentile(samples, 95)), 1)


def figures(condition: str, events: list[AnyEvent], window: tuple[float, float]) -> FieldRow:
    """The figures of one run from the agent's events, over ``window`` (monotonic seconds)."""
    row = FieldRow(condition)
    start, end = window
    links = of_kind(events, LinkChanged)
    ups = [e for e in links if e.state == "up"]
    if ups:
        row.candidate_type = ups[0].selected
        before = [e.t for e in links if e.state == "offer" and e.t <= ups[0].t]
        if before:
            row.connect_ms = round((ups[0].t - before[-1]) * 1000, 1)
    else:
        row.problems["connect_ms"] = "the link never came up"
    goals = [e for e in of_kind(events, GoalApplied) if start <= e.t <= end]
    row.goals_per_s = round(len(goals) / (end - start), 2)
    frames = of_kind(events, FrameSent)
    frame_sent = {e.frame: e.t for e in frames}
    commands = [
        (e.t, e.frame)
        for e in of_kind(events, TwistSent)
        if e.frame is not None and start <= e.t <= end
    ]
    glass = glass_to_command_ms(frame_sent, commands)
    if glass:
        row.glass_to_command_ms_p50 = round(float(np.percentile(glass, 50)), 1)
        row.glass_to_command_ms_p95 = round(float(np.percentile(glass, 95)), 1)
    else:
        row.problems["glass_to_command_ms_p50"] = "no tagged goal turned into a Twist"
    truth = [
        TruthSample(e.t, e.face_x, e.face_y, *VIDEO_SIZE)
        for e in frames
        if e.face_x is not None and e.face_y is not None
    ]
    poses = [
        PoseSample(e.t, e.x, e.y, e.theta)
        for e in of_kind(events, PoseReport)
        if start <= e.t <= end
    ]
    row.heading_error_deg_median = _round(
        heading_error_deg_median(heading_track(poses, truth, pixel_to_terrain), start)
    )
    row.stale_goals_applied = stale_goals_applied(events)
    return row


def samples_since(before: dict[str, Any], after: dict[str, Any]) -> list[float]:
    """The client's glass-to-glass samples taken between two readings of ``_GLASS_JS`` (a ring
    that holds the latest: a window longer than the ring keeps its last part)."""
    taken = int(after["count"]) - int(before["count"])
    return [float(ms) for ms in after["ms"][-taken:]] if taken > 0 else []


def stale_goals_applied(events: list[AnyEvent]) -> int:
    """Goals applied although a newer one (by seq, or by the frame it was computed from) had
    already been applied on the same link."""
    stale = 0
    newest_seq = newest_frame = -1
    for event in events:
        match event:
            case LinkChanged(state="up"):
                newest_seq = newest_frame = -1  # a new link: the relay counts again
            case GoalApplied(seq=seq, frame=frame):
                if seq <= newest_seq or (frame is not None and frame < newest_frame):
                    stale += 1
                newest_seq = max(newest_seq, seq)
                if frame is not None:
                    newest_frame = max(newest_frame, frame)
    return stale


def link_drop_times(
    events: list[AnyEvent], dark_at: float, back_at: float
) -> dict[str, float | None]:
    """Seconds from the last goal before the outage to the zero Twist, and from the link's
    return to the next applied goal."""
    goals = [e.t for e in of_kind(events, GoalApplied)]
    last = max((t for t in goals if t <= dark_at), default=None)
    stop = next(
        (
            e.t
            for e in of_kind(events, TwistSent)
            if e.seq is None and e.angular == 0 and last is not None and e.t > last
        ),
        None,
    )
    resumed = min((t for t in goals if t > back_at), default=None)
    return {
        "stop_after_s": _round(stop - last if stop is not None and last is not None else None, 3),
        "resume_after_s": _round(resumed - back_at if resumed is not None else None, 3),
    }


def _round(value: float | None, digits: int = 1) -> float | None:
    return None if value is None else round(value, digits)


def run(
    out: Path,
    quick: bool,
    conditions: Sequence[str] = ORDER,
    seconds: float | None = None,
    fps: float | None = None,
    provenance: Mapping[str, str] | None = None,
) -> dict[str, Any]:
    """Measure ``conditions`` (in the bench's order) and the video sender, each for ``seconds``
    if given (``--seconds``), the vehicle's camera at ``fps`` if given (``--fps``; the video
    sender's canvas keeps its own 30 frames/s); write ``field.json``, ``field.md`` and plots
    into ``out``."""
    # Imported here: Playwright and the lab are only needed when the field bench runs.
    from playwright.sync_api import sync_playwright

    from app.tools.bench import video
    from app.tools.lab import Lab
    from app.tools.lab.stack import field_stack

    window_s = seconds if seconds is not None else QUICK_WINDOW_S if quick else FULL_WINDOW_S
    load_before = os.getloadavg()[0]
    rows: list[FieldRow] = []
    drop: dict[str, float | None] = {"stop_after_s": None, "resume_after_s": None}
    with Lab() as lab, sync_playwright() as playwright:
        for name in (name for name in ORDER if name in conditions):
            lab.apply(name)
            log.info("field bench: %s", name)
            with field_stack(lab, playwright, out / "field" / name, fps) as stack:
                stack.start_piloting()
                deadline = time.monotonic() + FIRST_GOAL_TIMEOUT_S
                while not stack.events(GoalApplied) and time.monotonic() < deadline:
                    time.sleep(0.5)
                if not stack.events(GoalApplied):
                    row = FieldRow(name)
                    row.problems["all"] = f"no goal within {FIRST_GOAL_TIMEOUT_S:g} s"
                    rows.append(row)
                    continue
                time.sleep(SETTLE_S)
                frames_before = stack.client.evaluate(_VIDEO_FRAMES_JS)
                glass_before = stack.client.evaluate(_GLASS_JS)
                start = time.monotonic()
                if name == "link_drop":
                    time.sleep(OUTAGE_AT_S)
                    with lab.outage():
                        dark_at = time.monotonic()
                        time.sleep(lab.condition.outage_s)
                    back_at = time.monotonic()
                    time.sleep(max(0.0, start + window_s - time.monotonic()))
                    resume_deadline = back_at + RESUME_TIMEOUT_S
                    while not any(e.t > back_at for e in stack.events(GoalApplied)):
                        if time.monotonic() > resume_deadline:
                            break
                        time.sleep(0.5)
                    drop = link_drop_times(stack.all_events(), dark_at, back_at)
                else:
                    time.sleep(window_s)
                end = time.monotonic()
                frames_after = stack.client.evaluate(_VIDEO_FRAMES_JS)
                row = figures(name, stack.all_events(), (start, end))
                row.client_glass(samples_since(glass_before, stack.client.evaluate(_GLASS_JS)))
                if isinstance(frames_before, int) and isinstance(frames_after, int):
                    row.client_video_fps = round((frames_after - frames_before) / (end - start), 1)
                else:
                    row.problems["client_video_fps"] = "the client page shows no video element"
                rows.append(row)
        # Chromium's own video sender under a cap, per content hint: why the pages send
        # theirs with the hint they do (app/tools/bench/video.py).
        video_rows = video.measure(lab, playwright, quick, seconds)
    obj = {
        "field": [asdict(row) for row in rows],
        "link_drop": drop,
        "video": video_rows,
        "window_s": window_s,
        "fps": fps,
        "quick": quick,
        # Everything shares this machine's cores: the figures move with its load.
        "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "run": dict(provenance or {}),
    }
    write(out, obj)
    return obj


def write(out: Path, obj: dict[str, Any]) -> None:
    """``field.json``, ``field.md`` and two plots (latency, goals/s per condition)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "field.json").write_text(json.dumps(obj, indent=2) + "\n")
    keys = [
        "condition",
        "candidate_type",
        "connect_ms",
        "glass_to_command_ms_p50",
        "glass_to_command_ms_p95",
        "goals_per_s",
        "heading_error_deg_median",
        "stale_goals_applied",
        "client_video_fps",
        "client_glass_to_glass_ms_p50",
        "client_glass_to_glass_ms_p95",
    ]
    lines = [
        "# Field bench",
        "",
        f"Each condition measured over {obj['window_s']:g} s after the first goal "
        "(see `app/tools/bench/field.py`). Null: not measured, the reason is listed below. "
        f"Load average before/after: {obj.get('load_average')}.",
        "",
    ]
    run = obj.get("run")
    if run:
        lines += [
            f"Run {run['started']} on {run['machine']}, command `{run['command']}`.",
            "",
        ]
    lines += [
        "| " + " | ".join(keys) + " |",
        "| " + " | ".join("---" for _ in keys) + " |",
    ]
    for row in obj["field"]:
        lines.append("| " + " | ".join(_cell(row[k]) for k in keys) + " |")
    lines.append("")
    # The outage's two figures, when link_drop was among the conditions run.
    if any(row["condition"] == "link_drop" for row in obj["field"]):
        drop = obj["link_drop"]
        lines += [
            f"link_drop: zero Twist {_cell(drop['stop_after_s'])} s after the last goal (target "
            f"<= 0.75 s); goals again {_cell(drop['resume_after_s'])} s after the link came "
            "back (target <= 3 s).",
            "",
        ]
    if obj.get("video"):
        lines += [
            "Chromium's video sender, robot uplink capped, per content hint (received at the "
            "cloud; `app/tools/bench/video.py`):",
            "",
            "| condition | contentHint | degradationPreference | fps | width | kbit/s "
            "| limited by |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        for v in obj["video"]:
            cells = [_cell(v[key]) for key in VIDEO_COLUMNS]
            lines.append("| " + " | ".join(cells) + " |")
        lines.append("")
    for row in obj["field"]:
        for key, reason in row["problems"].items():
            lines.append(f"- {row['condition']} {key}: {reason}")
    lines.append("")
    lines.append("![latency](field-latency.png) ![goals per second](field-goals.png)")
    (out / "field.md").write_text("\n".join(lines) + "\n")
    _plot(out, obj)


def _cell(value: object) -> str:
    return "–" if value is None else str(value)


def _plot(out: Path, obj: dict[str, Any]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = obj["field"]
    names = [r["condition"] for r in rows]
    x = np.arange(len(names))
    fig, ax = plt.subplots(figsize=(8, 4))
    p50 = [r["glass_to_command_ms_p50"] or 0 for r in rows]
    p95 = [r["glass_to_command_ms_p95"] or 0 for r in rows]
    ax.bar(x - 0.2, p50, 0.4, label="p50")
    ax.bar(x + 0.2, p95, 0.4, label="p95")
    ax.set_xticks(x, names, rotation=20)
    ax.set_ylabel("glass-to-command (ms)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out / "field-latency.png", dpi=110)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.bar(x, [r["goals_per_s"] or 0 for r in rows])
    ax.set_xticks(x, names, rotation=20)
    ax.set_ylabel("goals applied per second")
    fig.tight_layout()
    fig.savefig(out / "field-goals.png", dpi=110)
    plt.close(fig)
