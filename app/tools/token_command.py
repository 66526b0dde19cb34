"""``autopilot token``: mint a token for one role in one room, and the page URL that carries it.

The secret comes from ``AUTOPILOT_SECRET``, never from the command line (where ``ps`` shows it).
The last line on stdout is ``{"token": ..., "url": ...}``; the token rides in the URL fragment,
which the browser keeps to itself, so it never reaches a server's access log.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from datetime import UTC, datetime

from app.arguments import positive_number
from app.protocol import tokens
from app.protocol.constants import Role
from app.protocol.urls import ServerUrlError, page_url, server_base

log = logging.getLogger(__name__)

SECRET_ENV = "AUTOPILOT_SECRET"
DEFAULT_SERVER = "http://127.0.0.1:8000"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot token``."""
    parser.add_argument("--room", required=True, help="the room the token admits to")
    parser.add_argument("--role", required=True, choices=tokens.ROLES, help="the role it grants")
    parser.add_argument(
        "--ttl",
        type=positive_number,
        default=tokens.DEFAULT_TTL_S,
        metavar="SECONDS",
        help=f"how long it stays valid (default {tokens.DEFAULT_TTL_S} s)",
    )
    parser.add_argument(
        "--server", default=DEFAULT_SERVER, help=f"server base URL (default {DEFAULT_SERVER})"
    )


def token_url(server: str, room: str, role: Role, token: str) -> str:
    """The role page for ``room`` on ``server``, with the token in the fragment."""
    return f"{page_url(server, role, room)}#token={token}"


def run(args: argparse.Namespace) -> int:
    """Print the token and URL as JSON on the last line; 1 with a reason on bad input."""
    secret = os.environ.get(SECRET_ENV, "")
    if not secret:
        log.error("cannot mint a token: %s is not set (the server's signing secret)", SECRET_ENV)
        return 1
    try:
        server_base(args.server)
    except ServerUrlError as exc:
        log.error("--server: %s", exc)
        return 1
    now = time.time()
    try:
        token = tokens.sign(secret, args.room, args.role, now=now, ttl_s=args.ttl)
    except ValueError as exc:
        log.error("cannot mint a token: %s", exc)
        return 1
    expires = datetime.fromtimestamp(now + args.ttl, UTC).isoformat(timespec="seconds")
    log.info("%s token for room %r, valid until %s", args.role, args.room, expires)
    sys.stdout.write(
        json.dumps({"token": token, "url": token_url(args.server, args.room, args.role, token)})
        + "\n"
    )
    return 0
