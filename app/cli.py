"""The ``autopilot`` command: one entry point, one subcommand per job.

Each subcommand lives in its own module exposing ``add_arguments(parser)`` and ``run(args) -> int``;
modules are imported only when their subcommand runs, so ``autopilot serve`` never loads aiortc.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from app.supervise import configure_logging

SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "serve": ("app.server.serve", "run the signaling server, role pages and simulated turtle"),
    "relay": ("app.relay.cli", "run the relay page in headless Chromium"),
    "vehicle": ("vehicle_agent.cli", "run the Python vehicle agent (aiortc)"),
    "demo": ("app.tools.demo", "run the whole system on an embedded default"),
    "parity": ("app.tools.parity", "compare OpenCV.js detections with Python OpenCV"),
    "replay": (
        "app.tools.replay",
        "replay a flight recording through the relay's vision and compare its goals",
    ),
    "bench": ("app.tools.bench.cli", "measure the running system and write a report"),
    "token": (
        "app.tools.token_command",
        "mint a token for one role in one room, signed with AUTOPILOT_SECRET (the server's)",
    ),
    "lab": (
        "app.tools.lab.cli",
        "build the field lab: NATs, TURN and network conditions (needs root: it makes network"
        " namespaces)",
    ),
}


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the command line and run one subcommand; returns the process exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(
        prog="autopilot",
        description="Pilot a ROS turtle from OpenCV.js analysis of its own WebRTC video.",
    )
    parser.add_argument("-v", "--verbose", action="store_true", help="log at DEBUG level")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # Only the chosen subcommand's module is imported; the others are listed by name.
    chosen = next((a for a in argv if a in SUBCOMMANDS), None)
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        if name == chosen:
            importlib.import_module(module_name).add_arguments(p)
    args = parser.parse_args(argv)
    configure_logging(args.verbose)
    module = importlib.import_module(SUBCOMMANDS[args.command][0])
    status: int = module.run(args)
    return status


if __name__ == "__main__":
    raise SystemExit(main())
