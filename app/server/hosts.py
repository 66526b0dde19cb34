"""The ``Host`` names a server without ``AUTOPILOT_SECRET`` answers: against DNS rebinding.

Without a secret nothing but the origin check stands between a web page and the robot, and that
check compares ``Origin`` with ``Host``. A page on ``evil.example`` whose name an attacker then
points at 127.0.0.1 (DNS rebinding) sends both as ``evil.example``: its requests look like the
server's own. The name is what gives it away: the server answers only the names it was started
for -- 127.0.0.1, localhost, [::1], the address it binds (every name and address of the machine
when it binds them all) and ``AUTOPILOT_ALLOWED_HOSTS``. With a secret every request needs a
token, which a rebinding page does not have, and any name is answered.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable, Iterable
from typing import Final
from urllib.parse import urlsplit

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send

from app.server import tls
from app.server.origins import refuse

log = logging.getLogger(__name__)

LOOPBACK_NAMES: Final = ("127.0.0.1", "localhost", "::1")
# Bound to these, the server is every address of the machine.
ANY_ADDRESS: Final = ("0.0.0.0", "::")
# Each refused name is logged once; past this many, further names are refused silently, so
# requests naming random hosts cannot flood the log.
MAX_LOGGED_NAMES: Final = 64


def host_name(host: str) -> str:
    """The name of a ``Host`` header (or an address to bind): lower case, the port and an IPv6
    literal's brackets left out; ``""`` when it names nothing."""
    try:
        return (urlsplit(f"//{host.strip()}").hostname or "").lower()
    except ValueError:
        return ""


def allowed_hosts(bound: str, extra: Iterable[str] = ()) -> frozenset[str]:
    """The names a server bound to ``bound`` answers without a secret: loopback, ``bound``
    itself (every name and address of the machine when ``bound`` is all of them) and ``extra``
    (``AUTOPILOT_ALLOWED_HOSTS``)."""
    names = {*LOOPBACK_NAMES, *(host_name(name) for name in extra)}
    if bound in ANY_ADDRESS:
        machine, addresses = tls.machine_names()
        names.update(machine)
        names.update(str(address) for address in addresses)
    else:
        names.add(host_name(bound))
    names.discard("")
    return frozenset(names)


class HostGuard:
    """ASGI middleware refusing HTTP requests (400) and WebSocket handshakes (403) whose
    ``Host`` is not among ``allowed`` (see :func:`allowed_hosts`)."""

    def __init__(
        self,
        app: ASGIApp,
        allowed: frozenset[str],
        on_refused: Callable[[], None] | None = None,
    ) -> None:
        self.app = app
        self.allowed = allowed
        # Told of each refusal (the metrics count them).
        self.on_refused = on_refused
        self._logged: set[str] = set()

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Refuse a name the server was not started for; pass everything else on untouched."""
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        host = Headers(scope=scope).get("host", "")
        name = host_name(host)
        if name in self.allowed:
            await self.app(scope, receive, send)
            return
        self._log(name or host)
        if self.on_refused is not None:
            self.on_refused()
        await refuse(scope, send, 400, "host not allowed")

    def _log(self, name: str) -> None:
        if name in self._logged or len(self._logged) >= MAX_LOGGED_NAMES:
            return
        self._logged.add(name)
        log.warning(
            "refused a request for host %r: this server answers only %s without"
            " AUTOPILOT_SECRET; to allow the name, set AUTOPILOT_ALLOWED_HOSTS='[%s]'",
            name[:100],
            ", ".join(sorted(self.allowed)),
            json.dumps(name[:100]),
        )
