"""``autopilot replay``: a flight recording as a regression test of the vision path.

The recorded camera images (``autopilot vehicle --record``, read through ``app/recording.py``) go
through the relay's own OpenCV.js analyzer in headless Chromium (the parity page's worker path:
``autopilot parity``), and the goal each one yields is compared with the goal the relay sent for
the same frame, paired by frame tag. ``--summary`` only lists what a recording holds.

Agreement rule: the replayed goal exists and lies within ``AGREE_FRACTION`` of the frame's width
of the recorded one. Not pixel equality: the relay analysed the decoded VP8 video, the replay the
recorded JPEG of the frame before encoding, and between full scans the relay searched a window
around the last target; the same target's goal moves by a few pixels, another target's by far
more. Goals the relay sent for frames that were not recorded (images are kept at ``--record-fps``,
goals come at the video's rate; the recorder keeps goals' own frames where it can) are not
compared.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from app.arguments import add_relay_profile
from app.protocol.events import GoalApplied
from app.protocol.relay_profiles import Profile
from app.recording import IMAGE_TOPIC, CutOff, RecordingError, events, images, summary
from app.tools.parity import open_harness

# A replayed goal agrees when within this fraction of the frame's width of the recorded one.
AGREE_FRACTION = 0.05
DEFAULT_MIN_AGREEMENT = 99.0
# Disagreements listed in the report (the count is always complete).
LISTED = 10


class UndecodableImage(ValueError):
    """A recorded image the browser cannot decode, though it looks like a JPEG."""


@dataclass
class Recording:
    """What replay needs from one or more MCAP files: goals by frame tag, and the images of
    their frames (how many images there were in all, and how many had no tag)."""

    images: dict[int, bytes] = field(default_factory=dict)
    goals: dict[int, GoalApplied] = field(default_factory=dict)
    images_recorded: int = 0
    untagged_images: int = 0


@dataclass
class Replay:
    """The comparison: counts, agreement and the first disagreements."""

    frames: int
    goals_recorded: int
    goals_compared: int = 0
    goals_replayed: int = 0
    agreed: int = 0
    disagreements: list[dict[str, Any]] = field(default_factory=list)

    @property
    def agreement_pct(self) -> float | None:
        """Share of compared goals that agree; None when none could be compared."""
        return 100.0 * self.agreed / self.goals_compared if self.goals_compared else None

    def as_json(self) -> dict[str, Any]:
        """The last line of ``--json``."""
        pct = self.agreement_pct
        return {**asdict(self), "agreement_pct": None if pct is None else round(pct, 2)}


def load(paths: Sequence[Path], on_cut_off: Callable[[CutOff], None] | None = None) -> Recording:
    """The applied goals, each by frame tag, and the recorded images (JPEG bytes) of their
    frames: read in two passes, so that only the images a goal names are held."""
    recording = Recording()
    for _, event in events(paths, on_cut_off):
        if isinstance(event, GoalApplied) and event.frame is not None:
            recording.goals[event.frame] = event
    # The cut is said once, on the first pass.
    for frame, jpeg in images(paths, lambda _: None):
        recording.images_recorded += 1
        if frame is None:
            recording.untagged_images += 1
        elif frame in recording.goals:
            recording.images[frame] = jpeg
    return recording


def compare(recording: Recording, analyse: Any, op: str | None = None) -> Replay:
    """Replay every recorded goal whose frame was recorded; ``analyse(jpeg, op)`` returns the
    replayed target ``{x, y}`` or None; ``op`` overrides the recorded operation."""
    replay = Replay(frames=recording.images_recorded, goals_recorded=len(recording.goals))
    for frame, goal in sorted(recording.goals.items()):
        jpeg = recording.images.get(frame)
        if jpeg is None:
            continue
        replay.goals_compared += 1
        try:
            target = analyse(jpeg, op or goal.op)
        except UndecodableImage as exc:
            raise UndecodableImage(f"the image of frame {frame} on {IMAGE_TOPIC}: {exc}") from exc
        distance = None
        if target is not None:
            replay.goals_replayed += 1
            distance = math.hypot(target["x"] - goal.x, target["y"] - goal.y)
            if distance <= AGREE_FRACTION * goal.w:
                replay.agreed += 1
                continue
        if len(replay.disagreements) < LISTED:
            replay.disagreements.append(
                {
                    "frame": frame,
                    "op": op or goal.op,
                    "recorded": [goal.x, goal.y],
                    "replayed": None if target is None else [target["x"], target["y"]],
                    "distance_px": None if distance is None else round(distance, 1),
                }
            )
    return replay


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot replay``."""
    parser.add_argument(
        "files", nargs="+", type=Path, metavar="FILE", help="MCAP files of one recording"
    )
    parser.add_argument("--op", help="replay with this operation (default: each goal's own)")
    add_relay_profile(parser, "relay profile the recording was made with")
    parser.add_argument(
        "--min-agreement",
        type=float,
        default=DEFAULT_MIN_AGREEMENT,
        metavar="PCT",
        help=f"exit 1 below this agreement (default {DEFAULT_MIN_AGREEMENT:g} %%)",
    )
    parser.add_argument(
        "--summary", action="store_true", help="list the channels, counts, duration and size"
    )
    parser.add_argument("--json", action="store_true", help="end with one JSON line")


def run(args: argparse.Namespace) -> int:
    """Replay (or summarise) the files: 1 below ``--min-agreement`` or with nothing to compare,
    2 on unreadable input. A file cut off is read up to its cut, and the cut said."""

    def cut_off(cut: CutOff) -> None:
        sys.stderr.write(f"autopilot replay: {cut}; reading what comes before it\n")

    try:
        if args.summary:
            return _print_summary(summary(args.files, cut_off), args.json)
        recording = load(args.files, cut_off)
    except RecordingError as exc:
        sys.stderr.write(f"autopilot replay: cannot read the recording: {exc}\n")
        return 2
    if not any(frame in recording.images for frame in recording.goals):
        # Before a browser is started for nothing: no goal has its image.
        sys.stderr.write(
            f"autopilot replay: nothing to compare: {len(recording.goals)} goals with a frame "
            f"tag, {recording.images_recorded} images, none of a goal's frame\n"
        )
        return 1
    profile: Profile = args.profile
    with open_harness() as harness:
        known = [operation.id for operation in harness.spec.operations]
        if args.op is not None and args.op not in known:
            sys.stderr.write(f"autopilot replay: unknown operation {args.op!r}; known: {known}\n")
            return 2

        def analyse(jpeg: bytes, op: str) -> dict[str, Any] | None:
            try:
                results = harness.results(jpeg, [op], profile)
            except ValueError as exc:  # the harness's word for an image it cannot decode
                raise UndecodableImage(str(exc)) from exc
            target: dict[str, Any] | None = results[op]["target"]
            return target

        try:
            replay = compare(recording, analyse, args.op)
        except UndecodableImage as exc:
            sys.stderr.write(f"autopilot replay: cannot read the recording: {exc}\n")
            return 2
    for item in replay.disagreements:
        sys.stdout.write(
            f"frame {item['frame']} {item['op']}: recorded {item['recorded']}, "
            f"replayed {item['replayed']}\n"
        )
    agreement = replay.agreement_pct
    assert agreement is not None  # a goal with its image was compared
    sys.stdout.write(
        f"{replay.frames} frames, {replay.goals_recorded} goals recorded, "
        f"{replay.goals_compared} on recorded frames, {replay.goals_replayed} replayed: "
        f"{agreement:.1f} % agree\n"
    )
    if recording.untagged_images:
        sys.stdout.write(
            f"{recording.untagged_images} images had no frame tag and could not be paired\n"
        )
    if args.json:
        sys.stdout.write(json.dumps(replay.as_json()) + "\n")
    return 0 if agreement >= args.min_agreement else 1


def _print_summary(found: dict[str, Any], as_json: bool) -> int:
    sys.stdout.write(
        f"{found['files']} file(s), {found['bytes'] / 1e6:.1f} MB, {found['duration_s']:.1f} s\n"
    )
    for topic, entry in sorted(found["channels"].items()):
        sys.stdout.write(f"  {topic:32} {entry['schema']:28} {entry['messages']:>8}\n")
    if as_json:
        sys.stdout.write(json.dumps(found) + "\n")
    return 0
