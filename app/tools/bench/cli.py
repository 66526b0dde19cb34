"""``autopilot bench``: run the real stack, measure it, write report.md, results.json and plots.

Runs itself inside a private network namespace (``scripts/in-netns``) when the machine allows it,
so that every WebRTC connection stays on this machine.
"""

from __future__ import annotations

import argparse
import asyncio
import datetime
import json
import logging
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.arguments import non_negative_integer, positive_integer, positive_number
from app.protocol.control import PROFILES
from app.protocol.opencv import OPENCV_BUILDS, RELAY_OPENCV_BUILD
from app.protocol.video import VIDEO_FPS
from app.resources import APP_DIR
from app.tools.bench import report
from app.tools.bench.field import ORDER as FIELD_CONDITIONS
from app.tools.bench.results import FIGURE_KEYS, POSITION_KEYS, ProfileRun, results

if TYPE_CHECKING:
    from playwright.async_api import Browser

log = logging.getLogger(__name__)

# Present in a source checkout (the repository root holds app/ and scripts/).
IN_NETNS = APP_DIR.parent / "scripts" / "in-netns"
# Set on the re-executed command so that a failed namespace set-up can never loop.
REEXEC_ENV = "AUTOPILOT_BENCH_REEXEC"

# performance.memory with real numbers, and window.gc() so heap samples follow a collection.
MEMORY_FLAGS = ["--enable-precise-memory-info", "--js-flags=--expose-gc"]

QUICK = {"default_s": 25.0, "thesis_s": 30.0, "follow_s": 25.0, "lock_s": 22.0, "frames": 13}
# The follow run spans three cycles of the synthetic face's path (20 s each).
# bench --recorder: seconds per run (with and without recording).
RECORDER_QUICK_S, RECORDER_FULL_S = 15.0, 60.0
# bench --foxglove: seconds measured in all (every phase of every round).
FOXGLOVE_QUICK_S, FOXGLOVE_FULL_S = 18.0, 60.0
# bench --relay-cost: seconds measured.
RELAY_COST_QUICK_S, RELAY_COST_FULL_S = 20.0, 60.0
# bench --faces --quick: photos of the set.
QUICK_PHOTOS = 4
# The shared face set, in a source checkout.
FACES_DIR = APP_DIR.parent / "tests" / "data" / "faces"
FULL = {"default_s": 60.0, "thesis_s": 60.0, "follow_s": 60.0, "lock_s": 60.0, "frames": 43}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot bench``."""
    parser.add_argument("--quick", action="store_true", help="short run (under 3 minutes)")
    parser.add_argument(
        "--soak",
        type=positive_number,
        metavar="MINUTES",
        help="run the default profile this long to measure memory growth",
    )
    parser.add_argument(
        "--seconds",
        type=positive_number,
        metavar="S",
        help="measure each profile (--field: each condition and video variant) for S seconds "
        "instead of --quick's or the full lengths; the synthetic face's sweep is shortened to "
        "S when longer, so even a short run sees it glide and leap",
    )
    parser.add_argument("--json", action="store_true", help="print the results object on stdout")
    parser.add_argument(
        "--field",
        action="store_true",
        help="run the stack in the field lab under each network condition (root)",
    )
    parser.add_argument(
        "--condition",
        action="append",
        choices=FIELD_CONDITIONS,
        metavar="NAME",
        help="with --field: measure only this condition (repeatable; default: all of "
        + ", ".join(FIELD_CONDITIONS)
        + ")",
    )
    parser.add_argument(
        "--fleet",
        action="store_true",
        help="measure the fleet instead: signaling across 2 instances on Redis, failover",
    )
    parser.add_argument(
        "--recorder",
        action="store_true",
        help="measure the flight recorder's cost instead: the agent's CPU and latency without"
        " and with --record",
    )
    parser.add_argument(
        "--foxglove",
        action="store_true",
        help="measure instead whether Foxglove viewers slow the agent: goal → Twist with no"
        " viewer, one reading and one that never reads, in rounds of one run (foxglove.md)",
    )
    parser.add_argument(
        "--relay-cost",
        action="store_true",
        help="measure where one relayed room's cores go instead: the relay's Chromium per"
        " thread and stage, codec counters, worker timers (relay-cost.md)",
    )
    parser.add_argument(
        "--baseline",
        action="store_true",
        help="with --relay-cost: also measure the fallback that encodes the video for each client"
        " (the relay's encoded transforms removed), the two forwards in alternation",
    )
    parser.add_argument(
        "--rounds",
        type=positive_integer,
        default=2,
        metavar="N",
        help="with --baseline: this many runs of each forward; with --recorder: this many"
        " alternating rounds of each mode (2)",
    )
    parser.add_argument(
        "--opencv-builds",
        action="store_true",
        help="time the cascades on each OpenCV.js build instead, side by side on the same frames,"
        " with Python as the baseline, and check the build the relay loads (opencv-builds.md)",
    )
    parser.add_argument(
        "--frames",
        type=positive_integer,
        metavar="N",
        help="time OpenCV.js against Python (--opencv-builds: each build) on N frames after the"
        f" warm-up (--opencv-builds: default {FULL['frames']:g}, --quick {QUICK['frames']:g};"
        " the stack's bench: 3 fewer)",
    )
    parser.add_argument(
        "--presses",
        type=positive_integer,
        metavar="N",
        help="the stack's bench: press the operator's arrow key N times, instead of the default"
        " count, to measure the manual override",
    )
    parser.add_argument(
        "--warmup",
        type=non_negative_integer,
        metavar="N",
        help="with --opencv-builds: leave the first N frames uncounted while both sides' JIT and"
        " caches settle (default: the bench's warm-up, see docs/bench/)",
    )
    parser.add_argument(
        "--repeats",
        type=positive_integer,
        metavar="N",
        help="with --opencv-builds: time each frame N times on each side and keep the fastest"
        " (default: the bench's, see docs/bench/)",
    )
    parser.add_argument(
        "--faces",
        action="store_true",
        help="measure face recall instead: the shared face set's photos at 24-192 px, upright and"
        " tilted, and face-free frames, through face, face_small and face_dnn (faces.md)",
    )
    parser.add_argument(
        "--photos",
        type=positive_integer,
        metavar="N",
        help=f"with --faces: the first N photos of the set (default all, --quick {QUICK_PHOTOS})",
    )
    parser.add_argument(
        "--camera",
        action="store_true",
        help="measure the simulated robot's camera instead: render and JPEG encode per frame,"
        " the arena against the empty arena (camera.md)",
    )
    parser.add_argument(
        "--onboard",
        action="store_true",
        help="measure the onboard law instead: the simulated diffdrive robot follows the walker"
        " with its own camera over the real stack (onboard.md)",
    )
    parser.add_argument(
        "--ops",
        metavar="OP[,OP...]",
        help="the operations to measure, side by side in one report: with --onboard, one walk"
        " each (default: face_small, and face_dnn when the relay offers it); with --relay-cost,"
        " one room each (default: the spec's default operation); with --opencv-builds, each on"
        " every frame (default: every operation that tracks)",
    )
    parser.add_argument(
        "--opencv",
        metavar="BUILD[,BUILD...]",
        help="with --relay-cost: the OpenCV.js builds the relay loads, one room each per"
        f" operation ({', '.join(OPENCV_BUILDS)}; default: the one it loads unless told,"
        f" {RELAY_OPENCV_BUILD})",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("bench-report"), help="report directory (bench-report/)"
    )
    parser.add_argument(
        "--fps",
        type=positive_number,
        default=VIDEO_FPS,
        help=f"frame rate of the synthetic video ({VIDEO_FPS:g}; --field: the vehicle camera's)",
    )


def run(args: argparse.Namespace) -> int:
    """Run the benchmark; 0 when every figure was measured, 1 when some could not be."""
    if args.condition and not args.field:
        log.error("--condition goes with --field")
        return 2
    if args.baseline and not args.relay_cost:
        log.error("--baseline goes with --relay-cost")
        return 2
    others = (args.field, args.fleet, args.recorder, args.foxglove, args.relay_cost, args.faces)
    if args.frames is not None and any((*others, args.camera, args.onboard)):
        log.error("--frames goes with --opencv-builds or the stack's own bench")
        return 2
    if args.presses is not None and any((*others, args.camera, args.onboard, args.opencv_builds)):
        log.error("--presses goes with the stack's own bench")
        return 2
    if args.warmup is not None and not args.opencv_builds:
        log.error("--warmup goes with --opencv-builds")
        return 2
    if args.repeats is not None and not args.opencv_builds:
        log.error("--repeats goes with --opencv-builds")
        return 2
    if args.photos is not None and not args.faces:
        log.error("--photos goes with --faces")
        return 2
    if args.ops is not None and not (args.onboard or args.relay_cost or args.opencv_builds):
        log.error("--ops goes with --onboard, --relay-cost or --opencv-builds")
        return 2
    if args.opencv is not None and not args.relay_cost:
        log.error("--opencv goes with --relay-cost")
        return 2
    try:
        if args.onboard:
            args.ops = ",".join(_onboard_ops(args.ops))
        elif args.relay_cost:
            args.ops = ",".join(_named(args.ops, _offered(), _offered()[:1]))
            args.opencv = ",".join(
                _named(
                    args.opencv,
                    list(OPENCV_BUILDS),
                    [RELAY_OPENCV_BUILD],
                    "--opencv",
                    "vendored",
                    "build",
                )
            )
        elif args.opencv_builds:
            from app.tools.bench.opencv_builds import tracking_ops

            args.ops = ",".join(
                _named(args.ops, tracking_ops(), tracking_ops(), among="that tracks")
            )
    except ValueError as exc:
        log.error("%s", exc)
        return 2
    if args.fleet:
        from app.tools.bench import fleet  # only the fleet bench needs Redis

        return fleet.run(args)
    if args.field:
        return _field(args)
    if args.camera:
        return _camera(args)
    if args.foxglove:  # no WebRTC: loopback sockets only
        return asyncio.run(_foxglove(args))
    if args.faces:
        return asyncio.run(_faces(args))
    if _can_enter_netns():
        _reexec_in_netns(args)
    if os.environ.get("AUTOPILOT_IN_NETNS") != "1":
        log.warning("no private network namespace here: WebRTC runs on the host's interfaces")
    if args.recorder:
        return asyncio.run(_recorder(args))
    if args.relay_cost:
        return asyncio.run(_relay_cost(args))
    if args.opencv_builds:
        return asyncio.run(_opencv_builds(args))
    if args.onboard:
        return asyncio.run(_onboard(args))
    obj = asyncio.run(_bench(args))
    if args.json:
        sys.stdout.write(json.dumps(obj, allow_nan=False) + "\n")
    missing = [key for key in FIGURE_KEYS if obj[key] is None or obj["thesis"][key] is None]
    missing += [f"follow {key}" for key in POSITION_KEYS if obj["follow"][key] is None]
    missing += list(obj["unmeasured"]["lock"]) + list(obj["unmeasured"]["override"])
    if missing:
        log.error("not measured: %s (reasons in %s)", ", ".join(missing), args.out / "report.md")
        return 1
    return 0


def _field(args: argparse.Namespace) -> int:
    # The lab builds namespaces of its own: no re-run inside the private one is needed.
    from app.tools.bench import field

    if os.geteuid() != 0:
        log.error("the field bench builds network namespaces: run it as root")
        return 2
    conditions = args.condition or FIELD_CONDITIONS
    obj = field.run(args.out, args.quick, conditions, args.seconds, args.fps, _provenance(args))
    if args.json:
        sys.stdout.write(json.dumps(obj, allow_nan=False) + "\n")
    unmeasured = [(r["condition"], k) for r in obj["field"] for k in r["problems"]]
    if "link_drop" in conditions and None in obj["link_drop"].values():
        unmeasured.append(("link_drop", "stop_after_s or resume_after_s"))
    if unmeasured:
        log.error("not all measured (reasons in %s)", args.out / "field.md")
        return 1
    return 0


def _camera(args: argparse.Namespace) -> int:
    """The simulated camera's cost: no network, so no namespace."""
    from app.tools.bench import camera  # OpenCV's renderer, which no other bench needs

    frames = camera.QUICK_FRAMES if args.quick else camera.FULL_FRAMES
    obj = camera.run(args.out, frames, args.fps)
    log.info("camera report: %s", args.out / "camera.md")
    if args.json:
        sys.stdout.write(json.dumps(obj, allow_nan=False) + "\n")
    return 0


async def _faces(args: argparse.Namespace) -> int:
    """Face recall in the relay's analyzer: no WebRTC, so no namespace. 1 when a target of
    face_dnn is not met."""
    from playwright.async_api import async_playwright

    from app.chromium import launch_options
    from app.server.serve import start_in_thread
    from app.tools.bench import faces

    photos = faces.photos(FACES_DIR)[: args.photos or (QUICK_PHOTOS if args.quick else None)]
    cases = faces.face_cases(photos) + faces.face_free_frames()
    load_before = os.getloadavg()[0]
    provenance = _provenance(args)
    server = start_in_thread()
    try:
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(**launch_options())
            try:
                outcomes, build = await faces.measure(browser, server.url, cases)
                browser_version = browser.version
            finally:
                await browser.close()
    finally:
        server.stop()
    figures = faces.figures(outcomes)
    found: dict[str, Any] = provenance | {
        "chromium": browser_version,
        "opencv": build,
        "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "photos": len(photos),
        "sizes": list(faces.SIZES),
        "tilts": list(faces.TILTS),
        "free_frames": sum(case.truth is None for case in cases),
        "ops": figures,
        "targets": faces.targets(figures),
    }
    log.info("faces report: %s", faces.write_report(args.out, found))
    if args.json:
        sys.stdout.write(json.dumps(found, allow_nan=False) + "\n")
    return 0 if all(check["met"] for check in found["targets"]) else 1


def _can_enter_netns() -> bool:
    if os.environ.get("AUTOPILOT_IN_NETNS") == "1" or os.environ.get(REEXEC_ENV) == "1":
        return False
    if not IN_NETNS.is_file() or os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    probe = subprocess.run(["unshare", "-n", "true"], capture_output=True, check=False)
    return probe.returncode == 0


def _reexec_in_netns(args: argparse.Namespace) -> None:
    argv = [str(IN_NETNS), sys.executable, "-m", "app.cli"]
    if args.verbose:
        argv.append("--verbose")
    argv.append("bench")
    if args.quick:
        argv.append("--quick")
    if args.soak is not None:
        argv += ["--soak", str(args.soak)]
    if args.seconds is not None:
        argv += ["--seconds", str(args.seconds)]
    if args.json:
        argv.append("--json")
    if args.recorder:
        argv += ["--recorder", "--rounds", str(args.rounds)]
    if args.relay_cost:
        argv += ["--relay-cost", "--ops", args.ops, "--opencv", args.opencv]
    if args.baseline:
        argv += ["--baseline", "--rounds", str(args.rounds)]
    if args.opencv_builds:
        argv += ["--opencv-builds", "--ops", args.ops]
    if args.onboard:
        argv += ["--onboard", "--ops", args.ops]
    if args.frames is not None:
        argv += ["--frames", str(args.frames)]
    if args.warmup is not None:
        argv += ["--warmup", str(args.warmup)]
    if args.repeats is not None:
        argv += ["--repeats", str(args.repeats)]
    if args.presses is not None:
        argv += ["--presses", str(args.presses)]
    argv += ["--out", str(args.out.resolve()), "--fps", str(args.fps)]
    log.info("re-running inside a private network namespace")
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(argv[0], argv, {**os.environ, REEXEC_ENV: "1"})


def _onboard_ops(asked: str | None) -> list[str]:
    """The operations ``--ops`` names (comma-separated), each one the relay offers; by default
    those of :data:`onboard.COMPARED` it offers. ValueError names an unknown one."""
    from app.tools.bench.onboard import COMPARED

    offered = _offered()
    return _named(asked, offered, [op for op in COMPARED if op in offered])


def _offered() -> list[str]:
    """The ids of the operations the relay offers, the spec's default first."""
    from app.resources import OPERATIONS_SPEC
    from app.vision.spec import load_spec

    spec = load_spec(OPERATIONS_SPEC)
    return [spec.default] + [op.id for op in spec.operations if op.id != spec.default]


def _named(
    asked: str | None,
    known: list[str],
    default: list[str],
    option: str = "--ops",
    among: str = "the relay offers",
    noun: str = "operation",
) -> list[str]:
    """What ``option`` names (comma-separated, each once, in order), each one of ``known``;
    ``default`` when not given. ValueError names an unknown one."""
    if asked is None:
        return default
    names = [name.strip() for name in asked.split(",") if name.strip()]
    unknown = [name for name in names if name not in known]
    if unknown or not names:
        raise ValueError(
            f"{option} {asked!r}: {', '.join(unknown) or 'no ' + noun} is not one {among}"
            f" ({', '.join(known)})"
        )
    return list(dict.fromkeys(names))


async def _onboard(args: argparse.Namespace) -> int:
    """The onboard law over the simulated arena, one walk per operation of ``--ops``: print
    the figures, write onboard.md; 1 when a figure could not be measured."""
    from playwright.async_api import async_playwright

    from app.chromium import launch_options
    from app.server.config import Settings
    from app.server.serve import start_in_thread
    from app.tools.bench import onboard

    seconds = args.seconds or (onboard.QUICK_S if args.quick else onboard.FULL_S)
    run_info: dict[str, Any] = _provenance(args)
    load_before = os.getloadavg()[0]
    server = start_in_thread(Settings(robot="diffdrive"))
    try:
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(**launch_options())
            try:
                with tempfile.TemporaryDirectory(prefix="autopilot-bench-onboard-") as tmp:
                    runs = {
                        op: await onboard.run(browser, server.url, seconds, args.fps, Path(tmp), op)
                        for op in args.ops.split(",")
                    }
            finally:
                await browser.close()
    finally:
        server.stop()
    # Other work on the machine slows every stage: the report says how busy it was.
    run_info |= {
        "netns": os.environ.get("AUTOPILOT_IN_NETNS") == "1",
        "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
    }
    log.info("onboard report: %s", onboard.write_report(args.out, runs, run_info))
    if args.json:
        shown = {
            op: {key: found.get(key) for key in onboard.FIGURE_KEYS}
            | {"problems": found["problems"]}
            for op, found in runs.items()
        }
        sys.stdout.write(json.dumps(shown) + "\n")
    return 1 if any(found["problems"] for found in runs.values()) else 0


async def _recorder(args: argparse.Namespace) -> int:
    """The flight recorder's cost: print the figures, write recorder.md; 1 if not measured."""
    from playwright.async_api import async_playwright

    from app.chromium import launch_options
    from app.server.serve import start_in_thread
    from app.tools.bench import recording

    seconds = args.seconds or (RECORDER_QUICK_S if args.quick else RECORDER_FULL_S)
    server = start_in_thread()
    try:
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(**launch_options())
            try:
                figures = await recording.run(browser, server.url, seconds, args.fps, args.rounds)
            finally:
                await browser.close()
    finally:
        server.stop()
    path = recording.write_report(args.out, figures)
    log.info("recorder report: %s", path)
    if args.json:
        sys.stdout.write(json.dumps(figures, allow_nan=False) + "\n")
    return 1 if figures["problems"] or "agent_cpu_increase_pct" not in figures else 0


async def _foxglove(args: argparse.Namespace) -> int:
    """Foxglove viewers and goal → Twist: print the figures, write foxglove.md; 1 if not
    measured."""
    from app.server.serve import start_in_thread
    from app.tools.bench import foxglove

    seconds = args.seconds or (FOXGLOVE_QUICK_S if args.quick else FOXGLOVE_FULL_S)
    server = start_in_thread()
    try:
        rounds = foxglove.QUICK_ROUNDS if args.quick else foxglove.ROUNDS
        figures = await foxglove.run(server.url, seconds, args.fps, rounds)
    finally:
        server.stop()
    path = foxglove.write_report(args.out, figures)
    log.info("Foxglove report: %s", path)
    if args.json:
        sys.stdout.write(json.dumps(figures, allow_nan=False) + "\n")
    measured = all(
        figures[phase]["p50_change_pct"] is not None for phase in ("viewer", "stuck viewer")
    )
    return 0 if measured else 1


async def _relay_cost(args: argparse.Namespace) -> int:
    """Where one room's relay cores go: print the figures, write relay-cost.md."""
    from playwright.async_api import async_playwright

    from app.chromium import launch_options
    from app.server.serve import start_in_thread
    from app.tools.bench import relaycost

    seconds = args.seconds or (RELAY_COST_QUICK_S if args.quick else RELAY_COST_FULL_S)
    # With --baseline: the forward as the relay does it and the fallback, in alternation; within
    # each, every build and every operation in turn, so that a machine whose speed drifts
    # biases none of them.
    forwards = list(relaycost.FORWARDS) * args.rounds if args.baseline else ["as is"]
    rooms = [
        relaycost.Room(op, build, forward)
        for forward in forwards
        for build in args.opencv.split(",")
        for op in args.ops.split(",")
    ]
    provenance = _provenance(args)
    runs = []
    server = start_in_thread()
    try:
        async with async_playwright() as playwright:
            for room in rooms:
                # The relay alone in a Chromium of its own: all its threads are the relay's.
                relay = await playwright.chromium.launch(
                    **launch_options(extra_args=[relaycost.MARKER])
                )
                client = await playwright.chromium.launch(**launch_options())
                try:
                    runs.append(
                        await relaycost.run(relay, client, server.url, seconds, args.fps, room)
                    )
                finally:
                    await relay.close()
                    await client.close()
    finally:
        server.stop()
    log.info("relay cost report: %s", relaycost.write_report(args.out, runs, provenance))
    if args.json:
        sys.stdout.write(json.dumps(relaycost.report_object(runs), allow_nan=False) + "\n")
    return 0


async def _opencv_builds(args: argparse.Namespace) -> int:
    """The cascades on each OpenCV.js build: print the figures, write opencv-builds.md; 1 when
    the build the relay loads is not the one the measurement chooses."""
    from playwright.async_api import async_playwright

    from app.chromium import launch_options
    from app.server.serve import start_in_thread
    from app.tools.bench import jsnative, opencv_builds

    counted = args.frames or int((QUICK if args.quick else FULL)["frames"])
    warmup = jsnative.WARMUP_FRAMES if args.warmup is None else args.warmup
    repeats = args.repeats or jsnative.REPEATS
    frames = jsnative.synthetic_frames(counted + warmup)
    started = datetime.datetime.now(datetime.UTC)
    load_before = os.getloadavg()[0]
    server = start_in_thread()
    try:
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(**launch_options())
            try:
                times = await opencv_builds.compare_builds(
                    browser,
                    server.url,
                    frames,
                    warmup=warmup,
                    ops=args.ops.split(","),
                    repeats=repeats,
                )
                browser_version = browser.version
            finally:
                await browser.close()
    finally:
        server.stop()
    found = opencv_builds.decide(
        {
            "command": _command(args),
            "started": started.isoformat(timespec="seconds"),
            "machine": _machine(),
            "chromium": browser_version,
            "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
            "frames": counted,
            "repeats": repeats,
            "ops": [opencv_builds.op_figures(t) for t in times],
        }
    )
    log.info("OpenCV.js builds report: %s", opencv_builds.write_report(args.out, found))
    if args.json:
        sys.stdout.write(json.dumps(found, allow_nan=False) + "\n")
    if found["choice"] != found["relay_loads"]:
        log.error(
            "measured: the relay should load the %s OpenCV.js (%s); it loads the %s"
            " (app/protocol/opencv.py)",
            found["choice"],
            found["reason"],
            found["relay_loads"],
        )
        return 1
    return 0


async def _bench(args: argparse.Namespace) -> dict[str, Any]:
    # Imported here: they pull in Playwright, aiortc and the server, which --help does not need.
    from playwright.async_api import async_playwright

    from app.chromium import launch_options
    from app.server.serve import start_in_thread
    from app.tools.bench import lock, override
    from app.tools.bench.jsnative import WARMUP_FRAMES

    plan = dict(QUICK if args.quick else FULL)
    if args.seconds is not None:
        plan.update(dict.fromkeys(("default_s", "thesis_s", "follow_s", "lock_s"), args.seconds))
    default_s = args.soak * 60.0 if args.soak else plan["default_s"]
    sweep_s = _sweep_s(args.seconds)
    started = datetime.datetime.now(datetime.UTC)
    load_before = os.getloadavg()[0]
    server = start_in_thread()
    try:
        async with async_playwright() as playwright:
            browser = await playwright.chromium.launch(**launch_options(extra_args=MEMORY_FLAGS))
            try:
                durations = {
                    "default": default_s,
                    "thesis": plan["thesis_s"],
                    "follow": plan["follow_s"],
                }
                runs = await _run_profiles(browser, server.url, durations, args.fps, sweep_s)
                with tempfile.TemporaryDirectory(prefix="autopilot-bench-lock-") as tmp:
                    lock_run = await lock.run(
                        browser, server.url, plan["lock_s"], args.fps, Path(tmp)
                    )
                with tempfile.TemporaryDirectory(prefix="autopilot-bench-override-") as tmp:
                    override_run = await override.run(
                        browser, server.url, args.fps, Path(tmp), args.presses
                    )
                    override_found = override.figures(*override_run)
                # After the stack is down, so that neither side shares its core with the video.
                frames = args.frames + WARMUP_FRAMES if args.frames else int(plan["frames"])
                await _compare_detection(browser, server.url, runs, frames)
                browser_version = browser.version
            finally:
                await browser.close()
    finally:
        server.stop()
    run_info = {
        "started": started.isoformat(timespec="seconds"),
        "machine": _machine(),
        "cores": os.cpu_count(),
        "command": _command(args),
        "netns": os.environ.get("AUTOPILOT_IN_NETNS") == "1",
        "chromium": browser_version,
        "fps": args.fps,
        "size": "640x480",
        "default_s": default_s,
        "thesis_s": plan["thesis_s"],
        "follow_s": plan["follow_s"],
        "lock_s": plan["lock_s"],
        "load_average": [round(load_before, 2), round(os.getloadavg()[0], 2)],
        "note": f"default profile {default_s:.0f} s, thesis profile {plan['thesis_s']:.0f} s,"
        f" follow profile {plan['follow_s']:.0f} s, target lock {plan['lock_s']:.0f} s"
        + ("" if sweep_s is None else f"; the face's sweep shortened to {sweep_s:g} s"),
    }
    obj = results(runs["default"], runs["thesis"], run_info, runs["follow"])
    lock.merge(obj, *lock_run)
    override.merge(obj, override_found)
    report.write(args.out, obj, runs["default"], runs["thesis"])
    return obj


async def _run_profiles(
    browser: Browser,
    server_url: str,
    durations: dict[str, float],
    fps: float,
    sweep_s: float | None = None,
) -> dict[str, ProfileRun]:
    """One stack run per profile; a profile whose stack fails keeps the reason, not numbers."""
    from app.tools.bench.stack import StackError, StackOptions, run_profile

    runs: dict[str, ProfileRun] = {}
    with tempfile.TemporaryDirectory(prefix="autopilot-bench-") as tmp:
        for profile, seconds in durations.items():
            # A soak samples memory every 30 s; short runs every 10 s.
            every = 30.0 if seconds >= 300 else 10.0
            options = StackOptions(profile, seconds, fps=fps, memory_every_s=every, sweep_s=sweep_s)
            try:
                runs[profile] = await run_profile(browser, server_url, options, Path(tmp))
            except StackError as exc:
                log.error("%s profile: %s", profile, exc)
                runs[profile] = ProfileRun(profile, problems=_all(str(exc)))
    return runs


def _sweep_s(seconds: float | None) -> float | None:
    """The synthetic face's cycle for a ``--seconds`` window: the window itself when shorter
    than the default cycle, so that it always holds both leaps (recall after a jump)."""
    from vehicle_agent.video import SweepPath

    return seconds if seconds is not None and seconds < SweepPath().cycle_s else None


async def _compare_detection(
    browser: Browser, server_url: str, runs: dict[str, ProfileRun], frames: int
) -> None:
    """OpenCV.js against Python on the same frames, per profile, into ``runs``."""
    from app.tools.bench.jsnative import compare, synthetic_frames

    # Detection runs with the relay profile a vehicle profile pairs with (follow: default's).
    relay_profiles = {name: PROFILES[name].relay_profile for name in runs}
    try:
        comparisons = await compare(
            browser,
            server_url,
            synthetic_frames(frames),
            tuple(sorted(set(relay_profiles.values()))),
        )
    except RuntimeError as exc:
        log.error("OpenCV.js against Python: %s", exc)
        for run in runs.values():
            run.problems.setdefault("js_over_native_ratio", str(exc))
        return
    for name, run in runs.items():
        comparison = comparisons[relay_profiles[name]]
        run.js_ms = comparison.js_ms
        run.native_ms = comparison.native_ms
        run.js_window_ms = comparison.js_window_ms


def _all(reason: str) -> dict[str, str]:
    return dict.fromkeys(FIGURE_KEYS, reason)


def _machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass  # not Linux: the platform name above will do
    return f"{os.cpu_count()} x {model}, Python {platform.python_version()}"


def _provenance(args: argparse.Namespace) -> dict[str, str]:
    """When, where and how a report's figures were measured, for its first lines."""
    started = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    return {"started": started, "machine": _machine(), "command": _command(args)}


def _command(args: argparse.Namespace) -> str:
    parts = ["autopilot bench"]
    if args.quick:
        parts.append("--quick")
    if args.field:
        parts.append("--field")
        parts += [f"--condition {name}" for name in args.condition or ()]
    if args.relay_cost:
        parts.append(f"--relay-cost --ops {args.ops} --opencv {args.opencv}")
    if args.baseline:
        parts.append(f"--baseline --rounds {args.rounds}")
    if args.onboard:
        parts.append(f"--onboard --ops {args.ops}")
    if args.opencv_builds:
        parts.append(f"--opencv-builds --ops {args.ops}")
    if args.faces:
        parts.append("--faces")
    if args.photos is not None:
        parts.append(f"--photos {args.photos}")
    if args.frames is not None:
        parts.append(f"--frames {args.frames}")
    if args.warmup is not None:
        parts.append(f"--warmup {args.warmup}")
    if args.repeats is not None:
        parts.append(f"--repeats {args.repeats}")
    if args.presses is not None:
        parts.append(f"--presses {args.presses}")
    if args.soak:
        parts.append(f"--soak {args.soak:g}")
    if args.seconds is not None:
        parts.append(f"--seconds {args.seconds:g}")
    if args.fps != VIDEO_FPS:
        parts.append(f"--fps {args.fps:g}")
    return " ".join(parts)
