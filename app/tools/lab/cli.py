"""``autopilot lab``: build the field lab, say how to use it, tear it down on Ctrl-C."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import threading
from types import FrameType

from app.tools.lab.conditions import CONDITIONS
from app.tools.lab.lab import Lab
from app.tools.lab.netns import LabError

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot lab``."""
    parser.add_argument(
        "--condition",
        choices=list(CONDITIONS),
        default="clean",
        help="network condition on the robot's link (default: clean)",
    )


def run(args: argparse.Namespace) -> int:
    """Build the lab, describe it, and keep it until SIGINT/SIGTERM; returns the exit status."""
    if os.geteuid() != 0:
        log.error("cannot build the lab: network namespaces need root")
        return 1
    stop = threading.Event()

    def _stop(signum: int, frame: FrameType | None) -> None:
        stop.set()

    previous = {sig: signal.signal(sig, _stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with Lab() as lab:
            applied = lab.apply(args.condition)
            for name, site in lab.sites.items():
                log.info("site %-8s %-15s namespace %s", name, site.address, site.namespace)
            log.info("condition %s: %s", applied.name, applied.description)
            if applied.ice_transport_policy == "relay":
                log.info("this condition wants ICE transport policy 'relay'")
            log.info("TURN %s and STUN %s (coturn, TURN REST)", lab.turn_url, lab.stun_url)
            log.info("TURN shared secret: %s", lab.turn_secret)
            log.info("run a command in a site: ip netns exec %s COMMAND", lab.namespace("robot"))
            log.info("lab is up; Ctrl-C tears it down")
            stop.wait()
            log.info("tearing the lab down")
    except LabError as exc:
        log.error("lab failed: %s", exc)
        return 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0
