"""Write a bench run up: ``results.json``, ``report.md`` and PNG plots in one directory."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.tools.bench.results import (
    FIGURE_KEYS,
    FOLLOW_TARGET,
    POSITION_KEYS,
    SOAK_TARGET_MINUTES,
    TARGETS,
    THESIS_PERIOD_S,
    THESIS_PROCESSING_MEAN_MS,
    THESIS_PROCESSING_SD_MS,
    ProfileRun,
)

if TYPE_CHECKING:
    from matplotlib.figure import Figure

log = logging.getLogger(__name__)

PLOTS = {
    "processing": "processing_delay.png",
    "heading": "heading.png",
    "latency": "glass_to_command.png",
    "js_native": "js_vs_native.png",
    "memory": "relay_memory.png",
}

LABELS = {
    "processing_ms_p50": "processing delay p50 (ms)",
    "processing_ms_p95": "processing delay p95 (ms)",
    "goals_per_s": "goals per second",
    "glass_to_command_ms_p50": "glass-to-command p50 (ms)",
    "glass_to_command_ms_p95": "glass-to-command p95 (ms)",
    "client_glass_to_glass_ms_p50": "client glass-to-glass p50 (ms)",
    "client_glass_to_glass_ms_p95": "client glass-to-glass p95 (ms)",
    "heading_error_deg_median": "median heading error (deg)",
    "js_over_native_ratio": "OpenCV.js / Python OpenCV",
    "memory_growth_pct": "relay memory growth (%)",
    "recall_after_jump_pct": "goals within 3 frames of a jump (%)",
    "position_error_m_p50": "follow position error p50 (m)",
    "position_error_m_p95": "follow position error p95 (m)",
    "lock_held_pct": "goals on the locked (smaller) face (%)",
    "override_ms_p50": "key event -> its Twist p50 (ms)",
    "override_ms_p95": "key event -> its Twist p95 (ms)",
    "deadman_stop_s": "last drive command -> zero Twist (s)",
}


def write(out: Path, results: dict[str, Any], default: ProfileRun, thesis: ProfileRun) -> None:
    """Write results.json, every plot and report.md into ``out`` (created if needed)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(results, indent=2, allow_nan=False) + "\n")
    runs = (default, thesis)
    _save(_processing_plot(runs), out / PLOTS["processing"])
    _save(_heading_plot(runs), out / PLOTS["heading"])
    _save(_latency_plot(runs), out / PLOTS["latency"])
    _save(_js_native_plot(runs), out / PLOTS["js_native"])
    _save(_memory_plot(runs), out / PLOTS["memory"])
    (out / "report.md").write_text(markdown(results))
    log.info("report written to %s", out / "report.md")


def _subplots(*grid: int, figsize: tuple[float, float], squeeze: bool = True) -> tuple[Figure, Any]:
    """A figure of its own (no pyplot, no display: ``savefig`` draws it with Agg) and its axes.

    matplotlib is imported here, not with the module: it costs half a CPU-second, which the
    test suite's collection and every bench that writes no plot need not pay.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(*grid, squeeze=squeeze)


def _save(fig: Figure, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _empty(ax: Any, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="grey")


def _processing_plot(runs: tuple[ProfileRun, ...]) -> Figure:
    """Per profile, in the manner of the thesis's Figure 31: the delay of each snapshot in order,
    with its mean and one standard deviation, next to the histogram."""
    fig, axes = _subplots(len(runs), 2, figsize=(11, 3.6 * len(runs)), squeeze=False)
    for (series_ax, hist_ax), run in zip(axes, runs, strict=True):
        delays = [ms for _, ms in run.processing]
        title = f"{run.profile} profile: snapshot taken -> goal sent"
        series_ax.set_title(title)
        hist_ax.set_title(f"{run.profile} profile: distribution")
        series_ax.set_xlabel("snapshot")
        series_ax.set_ylabel("delay (ms)")
        hist_ax.set_xlabel("delay (ms)")
        hist_ax.set_ylabel("snapshots")
        if not delays:
            _empty(series_ax, "no samples")
            _empty(hist_ax, "no samples")
            continue
        summary = run.processing_summary()
        assert summary is not None
        series_ax.plot(range(1, len(delays) + 1), delays, ".-", lw=0.6, ms=3, label="this run")
        series_ax.axhline(summary.mean, color="C1", label=f"mean {summary.mean:.1f} ms")
        series_ax.axhspan(
            summary.mean - summary.sd, summary.mean + summary.sd, color="C1", alpha=0.15
        )
        hist_ax.hist(delays, bins=min(40, max(5, len(delays) // 5)), color="C0")
        hist_ax.axvline(summary.p50, color="C1", label=f"p50 {summary.p50:.1f} ms")
        hist_ax.axvline(summary.p95, color="C3", ls="--", label=f"p95 {summary.p95:.1f} ms")
        if run.profile == "thesis":
            # On the same scale the thesis's own figure is comparable; on the default profile's
            # millisecond scale it would flatten everything.
            series_ax.axhline(
                THESIS_PROCESSING_MEAN_MS,
                color="k",
                ls=":",
                label=f"thesis {THESIS_PROCESSING_MEAN_MS:.0f} ms"
                f" (sd {THESIS_PROCESSING_SD_MS:.0f})",
            )
        series_ax.set_ylim(bottom=0)
        series_ax.legend(fontsize=8, loc="upper right")
        hist_ax.legend(fontsize=8)
    return fig


def _heading_plot(runs: tuple[ProfileRun, ...]) -> Figure:
    fig, axes = _subplots(len(runs), 1, figsize=(11, 3.4 * len(runs)), squeeze=False)
    for (ax,), run in zip(axes, runs, strict=True):
        ax.set_title(f"{run.profile} profile: turtle heading against the true face direction")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("angle (deg)")
        if not run.heading:
            _empty(ax, "no pose samples")
            continue
        t0 = run.heading[0].t
        ts = [s.t - t0 for s in run.heading]
        ax.plot(ts, [math.degrees(s.truth) for s in run.heading], color="k", lw=1, label="truth")
        ax.plot(
            ts, [math.degrees(s.heading) for s in run.heading], color="C0", lw=1, label="turtle"
        )
        if run.settle_at is not None:
            ax.axvline(run.settle_at - t0, color="grey", ls=":", label="settled")
        ax.legend(fontsize=8, loc="upper right")
    return fig


def _latency_plot(runs: tuple[ProfileRun, ...]) -> Figure:
    fig, axes = _subplots(1, len(runs), figsize=(5.5 * len(runs), 3.6), squeeze=False)
    for ax, run in zip(axes[0], runs, strict=True):
        latencies = run.glass_ms()
        ax.set_title(f"{run.profile} profile: frame sent -> Twist published")
        ax.set_xlabel("latency (ms)")
        ax.set_ylabel("frames")
        if not latencies:
            _empty(ax, "no frame traced to a Twist")
            continue
        ax.hist(latencies, bins=min(40, max(5, len(latencies) // 5)), color="C2")
        if run.profile == "default":  # the targets are the default profile's
            for key, style in (("glass_to_command_ms_p50", "-"), ("glass_to_command_ms_p95", "--")):
                target = next(t for t in TARGETS if t.key == key)
                ax.axvline(target.limit, color="C3", ls=style, label=target.text)
            ax.legend(fontsize=8)
    return fig


def _js_native_plot(runs: tuple[ProfileRun, ...]) -> Figure:
    fig, ax = _subplots(figsize=(7, 3.6))
    data, labels = [], []
    for run in runs:
        for side, values in (("OpenCV.js", run.js_ms), ("Python", run.native_ms)):
            if values:
                data.append(values)
                labels.append(f"{side}\n{run.profile}")
    ax.set_title(
        "detection time per frame: same frames and parameters, one thread each", fontsize=10
    )
    ax.set_ylabel("ms")
    if data:
        ax.boxplot(data, tick_labels=labels)
        ax.set_yscale("log")
    else:
        _empty(ax, "no detection timings")
    return fig


def _memory_plot(runs: tuple[ProfileRun, ...]) -> Figure:
    fig, (js_ax, wasm_ax) = _subplots(1, 2, figsize=(11, 3.6))
    js_ax.set_title("relay page JS heap (after GC)")
    wasm_ax.set_title("OpenCV WASM heap (vision worker)")
    for ax in (js_ax, wasm_ax):
        ax.set_xlabel("minutes of piloting")
        ax.set_ylabel("MiB")
    plotted = False
    for run in runs:
        if not run.memory:
            continue
        t0 = run.memory[0].t
        minutes = [(m.t - t0) / 60.0 for m in run.memory]
        if run.profile == "default" and run.memory_baseline_at is not None:
            for ax in (js_ax, wasm_ax):
                ax.axvline(
                    (run.memory_baseline_at - t0) / 60.0, color="grey", ls=":", label="growth from"
                )
        for ax, attr in ((js_ax, "js_heap"), (wasm_ax, "wasm_heap")):
            points = [
                (t, v / 2**20)
                for t, v in zip(minutes, (getattr(m, attr) for m in run.memory), strict=True)
                if v is not None
            ]
            if points:
                xs, ys = zip(*points, strict=True)
                ax.plot(xs, ys, ".-", label=f"{run.profile} profile")
                plotted = True
    if plotted:
        for ax in (js_ax, wasm_ax):
            ax.set_ylim(bottom=0)
            ax.legend(fontsize=8)
    else:
        _empty(js_ax, "no memory samples")
        _empty(wasm_ax, "no memory samples")
    return fig


def _soaked(results: dict[str, Any]) -> bool:
    """Whether the default profile ran as long as the memory target's soak."""
    return float(results["run"].get("default_s") or 0.0) >= SOAK_TARGET_MINUTES * 60.0


def _fmt(value: float | None) -> str:
    if value is None:
        return "not measured"
    return f"{value:.3g}" if abs(value) < 100 else f"{value:.0f}"


def _verdict(key: str, value: float | None, results: dict[str, Any]) -> str:
    target = next(t for t in TARGETS if t.key == key)
    if value is None:
        return "not measured"
    verdict = "met" if target.met(value) else "**not met**"
    minutes = results["details"]["default"].get("memory_minutes") or 0.0
    if key == "memory_growth_pct" and not _soaked(results):
        verdict += f" (over {minutes:.1f} min, not the 10-minute soak)"
    return verdict


def _limits(key: str, results: dict[str, Any]) -> str:
    """What the run's own numbers say limits a figure."""
    d = results["details"]["default"]
    run = results["run"]
    load = run.get("load_average")
    busy = (
        f", in this run with a load average of {max(load):.1f} on {run['cores']} cores"
        if load and run.get("cores")
        else ""
    )

    def p50(name: str) -> float | None:
        s = d.get(name)
        return s["p50"] if s else None

    if key.startswith("processing"):
        det, proc = p50("js_detect_ms"), p50("processing_ms")
        windowed = p50("js_window_detect_ms")
        tracked = (
            f" ({windowed:.1f} ms in the tracking window that most snapshots search)"
            if windowed is not None
            else ""
        )
        if det is not None and proc is not None:
            return (
                f"OpenCV.js detection alone takes {det:.1f} ms p50 on the whole frame{tracked}"
                f" (measured offline on the same kind of frame) of the {proc:.1f} ms p50; the"
                " rest is taking the snapshot, handing it to the worker and sending the goal, on"
                f" a CPU shared with the video encoder and decoders{busy}"
            )
        return "the relay's per-snapshot timings"
    if key == "goals_per_s":
        fps, window = d.get("frames_sent_per_s"), d.get("goal_window_s")
        proc = d.get("processing_ms")
        if fps is None or not window or not proc:
            return "at most one goal per decoded frame, so the video frame rate"
        return (
            f"at most one goal per decoded frame: the agent sent {fps:.1f} frames/s, the relay"
            f" analysed {d['relay_snapshots'] / window:.1f} snapshots/s, one at a time at"
            f" {proc['mean']:.0f} ms each on average{busy}"
        )
    if key.startswith("client_glass"):
        return (
            "the vehicle's encode, the network, the relay's forward (the vehicle's encoded frames"
            " passed through, or decoded and encoded again where the browser cannot), the"
            " client's jitter buffer and decode, and the wait for the next display refresh"
            f"{busy}"
        )
    if key.startswith("glass"):
        f2g, g2c = p50("frame_to_goal_ms"), p50("goal_to_command_ms")
        if f2g is not None and g2c is not None:
            return (
                f"frame sent -> goal received {f2g:.0f} ms p50 (encode, jitter buffer, decode,"
                f" relay); goal -> Twist {g2c:.0f} ms p50 (the control loop's pose-paced"
                f" publishing){busy}"
            )
        return "no per-stage split available"
    if key == "heading_error_deg_median":
        return (
            "the face keeps moving: the turtle lags it by the glass-to-command latency and its"
            " turn-rate limit"
        )
    if key == "recall_after_jump_pct":
        return (
            f"{d.get('face_jumps', 0)} appearances or jumps of the face while measuring; a goal"
            " must come from one of the 4 frames from the jump on, so any snapshot skipped"
            " (one in flight at a time) or a window that misses without a full scan costs recall"
        )
    if key == "js_over_native_ratio":
        return "OpenCV.js's WebAssembly build against the native wheel's SIMD-dispatched x86 code"
    if key == "memory_growth_pct":
        start, end = d.get("memory_start"), d.get("memory_end")
        if not start or not end:
            return "no memory samples"
        parts = []
        for name, attr in (("JS heap", "js_heap"), ("OpenCV WASM heap", "wasm_heap")):
            if start[attr] and end[attr]:
                parts.append(
                    f"{name} {start[attr] / 2**20:.2f} -> {end[attr] / 2**20:.2f} MiB"
                    f" ({(end[attr] - start[attr]) / start[attr] * 100:+.1f} %)"
                )
        minutes = d.get("memory_minutes") or 0.0
        text = "; ".join(parts) + f" over {minutes:.1f} min; the figure is the worse of the two"
        if not _soaked(results):
            text += (
                ". A short run sees the page's bounded logs and sample buffers still filling,"
                " so only a 10-minute `--soak 10` run speaks to leaks"
            )
        return text
    return ""


def _follow_section(results: dict[str, Any]) -> list[str]:
    """The follow profile's position error, when it ran."""
    follow = results.get("follow")
    if follow is None:
        return []
    p50, p95 = (follow[key] for key in POSITION_KEYS)
    verdict = "not measured" if p50 is None else ("met" if FOLLOW_TARGET.met(p50) else "missed")
    return [
        "",
        "## Follow profile",
        "",
        "The turtle drives toward the face's terrain point and holds a standoff from it, while"
        " the synthetic face glides and leaps along its path. Position error: at each pose, the"
        " absolute difference between the standoff and the distance from the turtle to the face's"
        " true terrain point, after a"
        " 1 s settle; it includes the time the turtle needs to catch up after each glide and"
        " leap.",
        "",
        f"- p50 {_fmt(p50)} m, p95 {_fmt(p95)} m; **{FOLLOW_TARGET.text}**: {verdict}.",
        f"- Glass-to-command p50 {_fmt(follow['glass_to_command_ms_p50'])} ms,"
        f" {_fmt(follow['goals_per_s'])} goals/s.",
    ]


def _lock_section(results: dict[str, Any]) -> list[str]:
    """The target lock in the two-face scene, when it ran."""
    target = results["targets"].get("lock_held_pct")
    if target is None:
        return []
    value, counts = results["lock_held_pct"], results["details"]["lock"]
    verdict = "not measured" if value is None else ("met" if value >= target["limit"] else "missed")
    return [
        "",
        "## Target lock",
        "",
        "Two faces drift slowly (the agent's `two-faces` video); once goals flow the client page"
        " clicks the smaller one. Share of the goals the vehicle received that lie on the smaller"
        f" face over {_fmt(counts['seconds'])} s: {counts['on_smaller']} of {counts['goals']}"
        f" ({counts['on_larger']} on the larger one, {counts['elsewhere']} elsewhere).",
        "",
        f"- {_fmt(value)} %; **{target['text']}**: {verdict}.",
    ]


def _override_section(results: dict[str, Any]) -> list[str]:
    """The operator's console: key → Twist, and the dead-man, when it ran."""
    counts = results["details"].get("override")
    if counts is None:
        return []
    lines = [
        "",
        "## Manual override",
        "",
        f"The client page takes the wheel and ArrowLeft is pressed {counts.get('presses', 0)}"
        " times, once a second (the bench's key event → the agent's first manual Twist, one"
        " monotonic clock);"
        " then, with the key held, the client page's script is paused: the vehicle's dead-man"
        f" ({_fmt(counts.get('deadman_s'))} s) must stop the turtle by itself.",
        "",
    ]
    for key in ("override_ms_p50", "deadman_stop_s"):
        target, value = results["targets"][key], results[key]
        met = value is not None and value <= target["limit"]
        verdict = "not measured" if value is None else "met" if met else "missed"
        lines.append(f"- {LABELS[key]}: {_fmt(value)}; **{target['text']}**: {verdict}.")
    lines.append(f"- {LABELS['override_ms_p95']}: {_fmt(results['override_ms_p95'])}.")
    lines.append(
        f"- Presses answered within their second: {counts.get('answered', 0)} of"
        f" {counts.get('presses', 0)} (the others are not in the figures)."
    )
    return lines


def markdown(results: dict[str, Any]) -> str:
    """The report as Markdown: figures against the thesis and the targets, then the plots."""
    run = results["run"]
    thesis = results["thesis"]
    d = results["details"]
    load = run.get("load_average")
    load_text = (
        f" Load average {load[0]:.1f} at the start and {load[1]:.1f} at the end (other work on"
        " the machine inflates every timing)."
        if load
        else ""
    )
    lines = [
        "# webrtc-autopilot benchmark",
        "",
        f"Run {run.get('started', '?')} on {run.get('machine', '?')}, command"
        f" `{run.get('command', 'autopilot bench')}`; {run.get('note', '')}.{load_text}",
        "",
        "The real stack: signaling server, headless relay page (Chromium), the Python vehicle agent"
        " with the synthetic face video, a headless client that pressed Start Piloting"
        f"{', inside a private network namespace' if run.get('netns') else ''}.",
        "",
        "## Figures",
        "",
        "| figure | default profile | thesis profile | target (default profile) | verdict |",
        "| --- | ---: | ---: | --- | --- |",
    ]
    for key in FIGURE_KEYS:
        target = next(t for t in TARGETS if t.key == key)
        lines.append(
            f"| {LABELS[key]} | {_fmt(results[key])} | {_fmt(thesis[key])} | {target.text} |"
            f" {_verdict(key, results[key], results)} |"
        )

    lines += ["", "## Against the thesis", ""]
    proc = d["default"]["processing_ms"]
    proc_thesis = d["thesis"]["processing_ms"]
    lines.append(
        f"The thesis measured {THESIS_PROCESSING_MEAN_MS:.0f} ms (sd {THESIS_PROCESSING_SD_MS:.0f}"
        f" ms) from snapshot to goal sent (its Figure 31) and acted every {THESIS_PERIOD_S} s"
        f" ({1 / THESIS_PERIOD_S:.2f} goals/s)."
    )
    if proc_thesis:
        lines.append(
            "The thesis profile (its 1.5 s snapshots and 1.1 s moves, full-resolution detection"
            f" with the tutorial parameters) measures a mean of {proc_thesis['mean']:.0f} ms"
            f" (sd {proc_thesis['sd']:.0f} ms) over {proc_thesis['n']} snapshots here: the"
            " thesis's work on this machine and OpenCV.js build. The default profile's further"
            " gain comes from its design: detection on a reduced frame in a Web Worker, a"
            " snapshot per decoded frame, and a closed control loop."
        )
    if proc:
        lines.append(
            f"The default profile: mean {proc['mean']:.1f} ms (sd {proc['sd']:.1f} ms) over"
            f" {proc['n']} snapshots, {THESIS_PROCESSING_MEAN_MS / proc['mean']:.0f}x less"
            " than the thesis."
        )
    snapshots = d["default"].get("relay_snapshots")
    if snapshots:
        lines.append(
            f"{d['default']['relay_goals_sent']} of its {snapshots} snapshots found the face and"
            " sent a goal (a snapshot without a face counts up to the end of its analysis)."
        )
    if results["goals_per_s"] is not None:
        lines.append(
            f"It sends {results['goals_per_s']:.1f} goals/s against the thesis's"
            f" {1 / THESIS_PERIOD_S:.2f}."
        )

    lines += ["", "## Against the targets", ""]
    for target in TARGETS:
        value = results[target.key]
        lines.append(
            f"- **{target.text}**: {_fmt(value)}, {_verdict(target.key, value, results)}."
            f" What limits it: {_limits(target.key, results)}."
        )

    lines += _follow_section(results)
    lines += _lock_section(results)
    lines += _override_section(results)

    missing = {p: m for p, m in results["unmeasured"].items() if m}
    if missing:
        lines += ["", "## Not measured", ""]
        for profile, reasons in missing.items():
            for key, reason in reasons.items():
                lines.append(f"- {profile} profile, {LABELS[key]}: {reason}.")

    lines += [
        "",
        "## Plots",
        "",
        f"![processing delay]({PLOTS['processing']})",
        "",
        f"![heading against truth]({PLOTS['heading']})",
        "",
        f"![glass-to-command latency]({PLOTS['latency']})",
        "",
        f"![OpenCV.js against Python OpenCV]({PLOTS['js_native']})",
        "",
        f"![relay memory]({PLOTS['memory']})",
        "",
        "## How each figure is measured",
        "",
        "- Processing delay: in the relay page, from taking the snapshot to sending its goal.",
        "- Goals per second: goals received by the vehicle while the face was in view.",
        "- Glass-to-command: the agent's time of sending frame n to its time of publishing the"
        " first Twist computed from the goal that echoes frame n (frame number drawn into the"
        " pixels, read back by the relay); one clock.",
        "- Client glass-to-glass: the agent's wall-clock time of handing frame n to its"
        " encoder (sent to the clients through the relay) to the moment the client page expects"
        " frame n on its screen (`requestVideoFrameCallback`'s `expectedDisplayTime`, frame"
        " number read from the presented pixels); one machine's clock.",
        "- Heading error: turtle heading against the direction from the turtle to the synthetic"
        " face's true centre mapped onto the terrain by the control law, after a 1 s settle.",
        "- OpenCV.js against Python: the same RGBA frames and operation parameters, OpenCV.js in"
        " the analyzer's Web Worker and `app.vision.spec.detect` with `cv2.setNumThreads(1)`;"
        " ratio of medians.",
        "- Memory: the relay page's `performance.memory.usedJSHeapSize` after a garbage collection"
        " and the OpenCV WASM heap size, sampled while piloting; growth runs from the first sample"
        " after a warm-up (a fifth of the run, at most 2 minutes, while the page's bounded buffers"
        " fill) to the last.",
        "",
    ]
    return "\n".join(lines)
