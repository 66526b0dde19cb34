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

from pydantic import ValidationError

from app.arguments import positive_number
from app.protocol import tokens
from app.protocol.urls import ServerUrlError, page_url, reachable_host, server_base

log = logging.getLogger(__name__)

MAKE_SECRET = (
    "export AUTOPILOT_SECRET=$(python3 -c 'import secrets; print(secrets.token_urlsafe(32))')"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``autopilot token``."""
    parser.add_argument(
        "--room", help="the room the token admits to (every room, and only so, for --role fleet)"
    )
    parser.add_argument(
        "--role",
        required=True,
        choices=tokens.TOKEN_ROLES,
        help="the role it grants; fleet: the fleet view (/fleet) of every room, and nothing else",
    )
    parser.add_argument(
        "--ttl",
        type=positive_number,
        default=tokens.DEFAULT_TTL_S,
        metavar="SECONDS",
        help=f"how long it stays valid (default {tokens.DEFAULT_TTL_S} s)",
    )
    parser.add_argument(
        "--server",
        help="server base URL, e.g. https://10.0.0.5:8000 (default: http:// on the host and port"
        " the server's settings give, AUTOPILOT_HOST and AUTOPILOT_PORT)",
    )


def token_url(server: str, room: str, role: tokens.TokenRole, token: str) -> str:
    """The role page for ``room`` on ``server`` (a fleet token's: ``/fleet``), with the token
    in the fragment."""
    if role == "fleet":
        return f"{server_base(server)}/fleet#token={token}"
    return f"{page_url(server, role, room)}#token={token}"


def run(args: argparse.Namespace) -> int:
    """Print the token and URL as JSON on the last line; 1 with a reason on bad input."""
    if args.role == "fleet":
        if args.room not in (None, tokens.ALL_ROOMS):
            log.error("a fleet token is for every room: leave out --room")
            return 1
        args.room = tokens.ALL_ROOMS
    elif args.room is None:
        log.error("--room is required for a %s token", args.role)
        return 1
    secret = os.environ.get(tokens.SECRET_ENV, "")
    if not secret:
        log.error(
            "cannot mint a token: %s is not set (the server's signing secret); make one with: %s",
            tokens.SECRET_ENV,
            MAKE_SECRET,
        )
        return 1
    if args.server is None:
        # The server's settings, read as it reads them.
        from app.server.config import Settings, describe_settings_error

        try:
            settings = Settings()
        except ValidationError as exc:
            log.error("cannot mint a token: %s", describe_settings_error(exc))
            return 1
        # Plain HTTP: TLS is a command-line choice of `autopilot serve`, not a setting.
        args.server = f"http://{reachable_host(settings.host)}:{settings.port}"
        log.info(
            "no --server given: assuming %s (pass --server if it runs elsewhere or on HTTPS)",
            args.server,
        )
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
    scope = "every room's fleet view" if args.role == "fleet" else f"room {args.room!r}"
    log.info("%s token for %s, valid until %s", args.role, scope, expires)
    sys.stdout.write(
        json.dumps({"token": token, "url": token_url(args.server, args.room, args.role, token)})
        + "\n"
    )
    return 0
