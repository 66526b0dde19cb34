"""``autopilot relay``: one relay page for one room, or with ``--pool`` every room that needs one.

Runs until SIGINT or SIGTERM, then closes its browser and exits with status 0.
"""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

from app.arguments import add_token_option, positive_integer
from app.chromium import BrowserNotFound, chromium_path
from app.metrics import add_metrics_arguments
from app.protocol import control, tokens
from app.relay.metrics import run_with_metrics
from app.relay.page import RelayError, check_server
from app.relay.service import RelayService

log = logging.getLogger(__name__)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot relay``."""
    parser.add_argument("--server", required=True, help="server base URL, e.g. http://host:8000")
    parser.add_argument("--room", default="default", help="room to join (default: default)")
    parser.add_argument("--name", default="relay", help="peer name (default: relay)")
    parser.add_argument(
        "--profile",
        choices=sorted(control.PROFILES),
        default=control.DEFAULT_PROFILE,
        help="the vehicle profile relayed for: the relay paces its snapshots as the relay profile"
        " it pairs with, and starts with its operation (onboard:"
        f" {control.PROFILES['onboard'].operation}) (default: {control.DEFAULT_PROFILE})",
    )
    add_token_option(parser, "relay")
    parser.add_argument(
        "--ca-file", type=Path, metavar="PEM", help="trust this CA for an https:// server"
    )
    parser.add_argument(
        "--pool",
        action="store_true",
        help="serve every room with a vehicle and no relay (needs Redis; --room is ignored)",
    )
    parser.add_argument(
        "--max-rooms", type=positive_integer, help="with --pool: serve at most N rooms"
    )
    parser.add_argument("--redis-url", help="with --pool: Redis URL (default: AUTOPILOT_REDIS_URL)")
    add_metrics_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run the headless relay (or, with ``--pool``, a relay pool) until SIGINT/SIGTERM."""
    if args.pool:
        return run_pool(args)
    try:
        check_server(args.server, args.ca_file)
        chromium_path()
        service = RelayService(
            args.server, args.room, args.name, args.profile, args.token, args.ca_file
        )
    except (RelayError, BrowserNotFound) as exc:
        log.error("%s", exc)
        return 1
    except (OSError, ValueError) as exc:
        log.error("cannot use --ca-file %s: %s", args.ca_file, exc)
        return 1
    status = run_with_metrics(args, service.run, service.pages)
    log.info("relay stopped")
    return status


def run_pool(args: argparse.Namespace) -> int:
    """``autopilot relay --pool``: serve rooms until SIGINT/SIGTERM."""
    redis_url = args.redis_url or os.environ.get("AUTOPILOT_REDIS_URL")
    if not redis_url:
        log.error("--pool needs Redis: pass --redis-url or set AUTOPILOT_REDIS_URL")
        return 1
    from app.relay.pool import RelayPool  # only a pool needs Redis

    secret = os.environ.get(tokens.SECRET_ENV) or None
    try:
        if secret is not None:
            tokens.check_secret(secret)
        check_server(args.server, args.ca_file)
        chromium_path()
    except (RelayError, BrowserNotFound, ValueError) as exc:
        log.error("%s", exc)
        return 1
    pool = RelayPool(
        args.server,
        redis_url,
        args.max_rooms,
        profile=args.profile,
        name=args.name,
        secret=secret,
        token=args.token,
        ca_file=args.ca_file,
    )
    status = run_with_metrics(args, pool.run, pool.pages)
    log.info("relay pool stopped")
    return status
