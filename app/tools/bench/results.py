"""What one bench run collected, and the headline figures computed from it.

A figure that could not be measured is ``None`` with a reason in ``unmeasured``: the bench never
puts a made-up number in its results.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from app.protocol.relay_profiles import THESIS_SNAPSHOT_PERIOD_MS
from app.tools.bench.stats import (
    FaceSample,
    HeadingSample,
    Summary,
    glass_to_command_ms,
    growth_pct,
    heading_error_deg_median,
    recall_after_jump_pct,
    summarize,
)

# The thesis's Figure 31: snapshot -> goal sent, and how often it acted.
THESIS_PROCESSING_MEAN_MS = 683.0
THESIS_PROCESSING_SD_MS = 196.0
THESIS_PERIOD_S = THESIS_SNAPSHOT_PERIOD_MS / 1000

# Headline keys, the same for each profile; the default profile's sit at the top level.
FIGURE_KEYS = (
    "processing_ms_p50",
    "processing_ms_p95",
    "goals_per_s",
    "glass_to_command_ms_p50",
    "glass_to_command_ms_p95",
    "client_glass_to_glass_ms_p50",
    "client_glass_to_glass_ms_p95",
    "heading_error_deg_median",
    "js_over_native_ratio",
    "memory_growth_pct",
    "recall_after_jump_pct",
)


@dataclass(frozen=True)
class Target:
    """A goal for one figure of the default profile."""

    key: str
    limit: float
    upper: bool  # True: the figure must stay at or below the limit
    text: str

    def met(self, value: float) -> bool:
        """Whether ``value`` reaches the target."""
        return value <= self.limit if self.upper else value >= self.limit


TARGETS = (
    Target("processing_ms_p50", 15.0, True, "processing p50 <= 15 ms"),
    Target("processing_ms_p95", 25.0, True, "processing p95 <= 25 ms"),
    Target("goals_per_s", 15.0, False, ">= 15 goals/s"),
    Target("glass_to_command_ms_p50", 120.0, True, "glass-to-command p50 <= 120 ms"),
    Target("glass_to_command_ms_p95", 200.0, True, "glass-to-command p95 <= 200 ms"),
    Target(
        "client_glass_to_glass_ms_p50", 60.0, True, "client glass-to-glass p50 <= 60 ms (loopback)"
    ),
    Target(
        "client_glass_to_glass_ms_p95",
        100.0,
        True,
        "client glass-to-glass p95 <= 100 ms (loopback)",
    ),
    Target("heading_error_deg_median", 5.0, True, "median heading error <= 5 deg"),
    Target("js_over_native_ratio", 1.3, True, "OpenCV.js / Python OpenCV <= 1.3"),
    Target("memory_growth_pct", 5.0, True, "memory growth <= 5 % over a 10-minute soak"),
    Target("recall_after_jump_pct", 99.0, False, ">= 99 % goals within 3 frames of a face jump"),
)

SOAK_TARGET_MINUTES = 10.0

# The follow profile's own figures: turtle to target point, minus the standoff.
POSITION_KEYS = ("position_error_m_p50", "position_error_m_p95")
FOLLOW_TARGET = Target(
    "position_error_m_p50", 0.3, True, "follow: position error p50 <= 0.3 m (face moving)"
)


@dataclass(frozen=True)
class MemorySample:
    """Relay memory at one moment: JS heap in use and the size of OpenCV's WASM heap (bytes)."""

    t: float
    js_heap: float | None
    wasm_heap: float | None


@dataclass
class ProfileRun:
    """Raw samples from running the stack under one profile. Times are seconds on one clock."""

    profile: str
    # (time, ms) per snapshot that produced a goal, snapshot taken -> goal sent, in the relay.
    processing: list[tuple[float, float]] = field(default_factory=list)
    # Snapshots the relay analysed and goals it sent over the window (its own counters).
    snapshots: int = 0
    relay_goals: int = 0
    # Goals received by the vehicle, with the frame tag they echo (None when untagged).
    goals: list[tuple[float, int | None]] = field(default_factory=list)
    # Window over which goals were counted, while the face was in view.
    window: tuple[float, float] | None = None
    frame_sent: dict[int, float] = field(default_factory=dict)
    # The true face centre of every frame sent, the frame size, and each goal's target by frame.
    face: list[FaceSample] = field(default_factory=list)
    frame_size: tuple[int, int] = (0, 0)
    goal_points: dict[int, tuple[float, float]] = field(default_factory=dict)
    # Published Twists with the frame tag of the goal they were computed from.
    commands: list[tuple[float, int]] = field(default_factory=list)
    heading: list[HeadingSample] = field(default_factory=list)
    settle_at: float | None = None
    js_ms: list[float] = field(default_factory=list)
    native_ms: list[float] = field(default_factory=list)
    # OpenCV.js detection in the tracking window around the face, same frames as js_ms.
    js_window_ms: list[float] = field(default_factory=list)
    memory: list[MemorySample] = field(default_factory=list)
    # Growth is measured from the first memory sample at or after this time.
    memory_baseline_at: float | None = None
    # Why a measurement is missing, keyed by figure name; filled by the runner as it goes.
    problems: dict[str, str] = field(default_factory=dict)
    # Follow profile: (time, metres off the standoff from the true target point) per pose.
    position_error: list[tuple[float, float]] = field(default_factory=list)
    # Cores the agent process used over the window (its CPU time / the window's length).
    agent_cores: float | None = None
    # Vehicle capture -> presentation at the client page, ms, each frame it measured while
    # measuring (its window.autopilotHealth; the vehicle's and the client's wall clocks).
    client_glass: list[float] = field(default_factory=list)

    def position_error_summary(self) -> Summary | None:
        """Distribution of the follow profile's position error after the settle time."""
        after = self.settle_at if self.settle_at is not None else float("-inf")
        return summarize([m for t, m in self.position_error if t >= after])

    def processing_summary(self) -> Summary | None:
        """Distribution of the snapshot -> goal-sent delay."""
        return summarize([ms for _, ms in self.processing])

    def glass_ms(self) -> list[float]:
        """Glass-to-command latencies in ms."""
        return glass_to_command_ms(self.frame_sent, self.commands)

    def goal_to_command_ms(self) -> list[float]:
        """Goal received -> first Twist from it, in ms: the vehicle's share of glass-to-command."""
        received: dict[int, float] = {}
        for t, frame in self.goals:
            if frame is not None and frame not in received:
                received[frame] = t
        return glass_to_command_ms(received, self.commands)

    def recall(self) -> tuple[float | None, int]:
        """Recall after the face appears or jumps, over the frames sent while measuring."""
        start, end = self.window or (float("-inf"), float("inf"))
        track = [s for s in self.face if start <= self.frame_sent.get(s.frame, start - 1) < end]
        return recall_after_jump_pct(track, self.goal_points, *self.frame_size)

    def frame_to_goal_ms(self) -> list[float]:
        """Frame sent -> its goal received, in ms: video, relay and data channel together."""
        return glass_to_command_ms(
            self.frame_sent, [(t, f) for t, f in self.goals if f is not None]
        )


def memory_baseline(run: ProfileRun) -> MemorySample | None:
    """The sample growth is measured from: the first one at or after the baseline time."""
    start = run.memory_baseline_at if run.memory_baseline_at is not None else float("-inf")
    return next((m for m in run.memory if m.t >= start), None)


def _growth(run: ProfileRun, attr: str) -> float | None:
    baseline = memory_baseline(run)
    if baseline is None or baseline is run.memory[-1]:
        return None
    first, last = getattr(baseline, attr), getattr(run.memory[-1], attr)
    if first is None or last is None or first <= 0:
        return None
    return growth_pct(first, last)


def memory_growths(run: ProfileRun) -> dict[str, float | None]:
    """Growth in percent of the JS heap and of the WASM heap, baseline sample to last."""
    return {attr: _growth(run, attr) for attr in ("js_heap", "wasm_heap")}


def figures(run: ProfileRun) -> tuple[dict[str, float | None], dict[str, str]]:
    """The headline figures of one profile, and the reason for each one that is missing."""
    values: dict[str, float | None] = dict.fromkeys(FIGURE_KEYS)
    missing: dict[str, str] = {}

    def why(key: str, default: str) -> None:
        missing[key] = run.problems.get(key, default)

    def percentiles(prefix: str, summary: Summary | None, reason: str) -> None:
        for name in ("p50", "p95"):
            if summary is None:
                why(f"{prefix}_{name}", reason)
            else:
                values[f"{prefix}_{name}"] = getattr(summary, name)

    percentiles(
        "processing_ms", run.processing_summary(), "the relay reported no processing samples"
    )

    if run.window is None or not run.goals:
        why("goals_per_s", "no goals reached the vehicle")
    else:
        start, end = run.window
        values["goals_per_s"] = sum(1 for t, _ in run.goals if start <= t < end) / (end - start)

    percentiles(
        "glass_to_command_ms",
        summarize(run.glass_ms()),
        "no Twist could be traced back to a tagged frame",
    )

    percentiles(
        "client_glass_to_glass_ms",
        summarize(run.client_glass),
        "the client page measured no frame (no tagged frame with a known capture time)",
    )

    heading = (
        heading_error_deg_median(run.heading, run.settle_at) if run.settle_at is not None else None
    )
    if heading is None:
        why("heading_error_deg_median", "no pose after the settle time with a known face position")
    values["heading_error_deg_median"] = heading

    js, native = summarize(run.js_ms), summarize(run.native_ms)
    if js is None or native is None or native.p50 <= 0:
        why("js_over_native_ratio", "detection times missing on one side")
    else:
        values["js_over_native_ratio"] = js.p50 / native.p50

    growths = [g for g in memory_growths(run).values() if g is not None]
    if not growths:
        why("memory_growth_pct", "no memory samples after the warm-up and before the end")
    else:
        # The worse of the two heaps: a leak in either one is a leak.
        values["memory_growth_pct"] = max(growths)

    recall, jumps = run.recall()
    if recall is None:
        why("recall_after_jump_pct", "the face neither appeared nor jumped while measuring")
    values["recall_after_jump_pct"] = recall

    for key, value in values.items():
        if value is not None and not math.isfinite(value):
            values[key] = None
            missing[key] = f"computed a non-finite value ({value})"
    return values, missing


def follow_figures(run: ProfileRun) -> tuple[dict[str, float | None], dict[str, str]]:
    """The follow profile's figures (every profile figure plus its position error)."""
    values, missing = figures(run)
    summary = run.position_error_summary()
    for name in ("p50", "p95"):
        key = f"position_error_m_{name}"
        values[key] = getattr(summary, name) if summary is not None else None
        if summary is None:
            missing[key] = run.problems.get(key, "no pose after the settle time with a known face")
    return values, missing


def details(run: ProfileRun) -> dict[str, Any]:
    """Distributions behind the headline figures, for results.json and the report."""

    def summary(values: list[float]) -> dict[str, float | int] | None:
        s = summarize(values)
        return s.as_dict() if s is not None else None

    first = memory_baseline(run)
    last = run.memory[-1] if run.memory else None
    return {
        "processing_ms": summary([ms for _, ms in run.processing]),
        "glass_to_command_ms": summary(run.glass_ms()),
        "frame_to_goal_ms": summary(run.frame_to_goal_ms()),
        "goal_to_command_ms": summary(run.goal_to_command_ms()),
        "client_glass_to_glass_ms": summary(run.client_glass),
        "frames_sent_per_s": (
            sum(1 for t in run.frame_sent.values() if run.window[0] <= t < run.window[1])
            / (run.window[1] - run.window[0])
            if run.window
            else None
        ),
        "relay_snapshots": run.snapshots,
        "relay_goals_sent": run.relay_goals,
        "goals_received": len(run.goals),
        "goal_window_s": (run.window[1] - run.window[0]) if run.window else None,
        "face_jumps": run.recall()[1],
        "js_detect_ms": summary(run.js_ms),
        "js_window_detect_ms": summary(run.js_window_ms),
        "native_detect_ms": summary(run.native_ms),
        "heading_samples": len(run.heading),
        "position_error_m": (
            s.as_dict() if (s := run.position_error_summary()) is not None else None
        ),
        "memory_start": vars(first) if first else None,
        "memory_end": vars(last) if last else None,
        "memory_growth_pct": memory_growths(run),
        "memory_minutes": (last.t - first.t) / 60.0 if first and last else None,
        # Minutes since the first sample, JS heap and WASM heap in bytes: the whole trend.
        "memory_series": [
            [round((m.t - run.memory[0].t) / 60.0, 3), m.js_heap, m.wasm_heap] for m in run.memory
        ],
    }


def results(
    default: ProfileRun,
    thesis: ProfileRun,
    run_info: dict[str, Any],
    follow: ProfileRun | None = None,
) -> dict[str, Any]:
    """The results object: default-profile figures at the top, the thesis profile's under
    ``thesis`` (and the follow profile's under ``follow`` when it ran), distributions under
    ``details`` and reasons for any missing figure."""
    default_values, default_missing = figures(default)
    thesis_values, thesis_missing = figures(thesis)
    extra: dict[str, Any] = {}
    unmeasured = {"default": default_missing, "thesis": thesis_missing}
    more_details = {}
    if follow is not None:
        extra["follow"], unmeasured["follow"] = follow_figures(follow)
        more_details["follow"] = details(follow)
    targets = (*TARGETS, FOLLOW_TARGET) if follow is not None else TARGETS
    return {
        **default_values,
        "thesis": thesis_values,
        **extra,
        "unmeasured": unmeasured,
        "details": {"default": details(default), "thesis": details(thesis), **more_details},
        "targets": {t.key: {"limit": t.limit, "upper": t.upper, "text": t.text} for t in targets},
        "thesis_reference": {
            "processing_ms_mean": THESIS_PROCESSING_MEAN_MS,
            "processing_ms_sd": THESIS_PROCESSING_SD_MS,
            "period_s": THESIS_PERIOD_S,
        },
        "run": run_info,
    }
