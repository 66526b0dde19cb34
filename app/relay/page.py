"""The relay page, as the processes that run it in headless Chromium see it.

What :mod:`app.relay.service` and :mod:`app.relay.pool` share: the page's address, the check
that the server answers before a browser starts, and the window its goal rate is read over.
"""

from __future__ import annotations

import ssl
import urllib.error
import urllib.request
from pathlib import Path
from typing import Final

from app.protocol.urls import ServerUrlError, page_url, server_base, untrusted_hint

PAGE_LOAD_TIMEOUT_MS: Final = 30_000
# Goals per second are counted over this window of the page's recent goal times.
RATE_WINDOW_S: Final = 2.0


class RelayError(RuntimeError):
    """The relay cannot start at all (no browser, server unreachable)."""


def relay_url(server: str, room: str, name: str, profile: str, token: str | None = None) -> str:
    """The relay page URL that joins ``room`` unattended, without a video preview nobody
    watches; the token rides in the fragment, which never reaches the server's access log."""
    url = page_url(server, "relay", room, name=name, auto=1, profile=profile, preview=0)
    return url + (f"#token={token}" if token else "")


def loggable(url: str) -> str:
    """``url`` without its fragment, which may hold a token."""
    return url.split("#", 1)[0]


def check_server(server: str, ca_file: Path | None = None) -> None:
    """Fail fast, with the reason, when ``server`` does not answer ``/healthz`` (over HTTPS:
    with a certificate the system or ``ca_file`` trusts)."""
    try:
        base = server_base(server)
    except ServerUrlError as exc:
        raise RelayError(str(exc)) from None
    try:
        context = ssl.create_default_context(cafile=None if ca_file is None else str(ca_file))
        with urllib.request.urlopen(f"{base}/healthz", timeout=10, context=context) as response:
            response.read()
    except (urllib.error.URLError, OSError) as exc:
        raise RelayError(
            f"cannot reach the server at {server}: {exc}{untrusted_hint(exc)}"
        ) from exc
