"""Which web pages may open a WebSocket or change state: the server's own plus an allow-list.

Browsers send ``Origin`` on every WebSocket handshake and cross-site request, and a page cannot
forge it. A request whose ``Origin`` is neither this server nor listed in
``AUTOPILOT_ALLOWED_ORIGINS`` comes from some other site the operator has open, and is refused.
Tools (the agent, roslibpy, curl) send no ``Origin`` at all; they are not a browser a hostile
site could drive, so they are judged by their token alone.
"""

from __future__ import annotations

import enum
import json
import logging
from collections.abc import Callable, Iterable
from urllib.parse import urlsplit

from starlette.datastructures import Headers
from starlette.types import ASGIApp, Receive, Scope, Send

log = logging.getLogger(__name__)

DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}


class Verdict(enum.Enum):
    """Where a request comes from, as far as its ``Origin`` header tells."""

    OWN = "own"  # a page this server served
    LISTED = "listed"  # a page from an origin the operator allowed
    ABSENT = "absent"  # no Origin: a tool, not a browser page; its token decides
    FOREIGN = "foreign"  # some other site: refused

    @property
    def admitted(self) -> bool:
        """True unless the request comes from a site that is neither ours nor allowed."""
        return self is not Verdict.FOREIGN


def normalise(origin: str) -> str:
    """``scheme://host[:port]`` in lower case, the scheme's default port left out.

    Raises ``ValueError`` for anything that is not an http(s) origin.
    """
    parts = urlsplit(origin.strip())
    scheme = parts.scheme.lower()
    if scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"an origin looks like https://host[:port], not {origin!r}")
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username:
        raise ValueError(f"an origin has no path, query or user: {origin!r}")
    host = parts.hostname.lower()
    if ":" in host:
        host = f"[{host}]"  # IPv6 literal
    port = parts.port
    return f"{scheme}://{host}" + ("" if port in (None, DEFAULT_PORTS[scheme]) else f":{port}")


def judge(origin: str | None, host: str | None, allowed: Iterable[str] = ()) -> Verdict:
    """The :class:`Verdict` on a request with headers ``Origin: origin`` and ``Host: host``.

    Own origin means the page was loaded from the host and port this request was sent to; the
    scheme is not compared because one port serves one scheme (and a TLS-terminating proxy in
    front would make the two differ). ``allowed`` are origins as :func:`normalise` accepts them.
    """
    if origin is None:
        return Verdict.ABSENT
    try:
        page = normalise(origin)
    except ValueError:
        return Verdict.FOREIGN  # "null" (sandboxed frames, file://) and anything malformed
    if host is not None and _authority(page) == _host_header(host, urlsplit(page).scheme):
        return Verdict.OWN
    if page in {normalise(a) for a in allowed}:
        return Verdict.LISTED
    return Verdict.FOREIGN


def _authority(normalised: str) -> str:
    return normalised.split("://", 1)[1]


def _host_header(host: str, scheme: str) -> str:
    """The Host header in :func:`normalise`'s form, the default port of ``scheme`` left out."""
    try:
        return _authority(normalise(f"{scheme}://{host}"))
    except ValueError:
        return ""


# Requests that only read; every other method changes state and must come from an allowed page.
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


class OriginGuard:
    """ASGI middleware refusing, with 403, WebSocket handshakes and state-changing requests
    whose ``Origin`` is neither this server nor in ``allowed``.

    A WebSocket is refused before ``accept()``: closing a handshake that was never accepted
    makes the server answer it with HTTP 403, so a foreign page never gets an open socket.
    """

    def __init__(
        self,
        app: ASGIApp,
        allowed: Iterable[str] = (),
        on_refused: Callable[[], None] | None = None,
    ) -> None:
        self.app = app
        self.allowed = [normalise(origin) for origin in allowed]
        # Told of each refusal (the metrics count them).
        self.on_refused = on_refused

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Refuse a foreign origin; pass everything else on untouched."""
        guarded = scope["type"] == "websocket" or (
            scope["type"] == "http" and scope["method"] not in SAFE_METHODS
        )
        if guarded:
            headers = Headers(scope=scope)
            origin = headers.get("origin")
            if not judge(origin, headers.get("host"), self.allowed).admitted:
                log.warning("refused %s %s from origin %r", scope["type"], scope["path"], origin)
                if self.on_refused is not None:
                    self.on_refused()
                await self._refuse(scope, send)
                return
        await self.app(scope, receive, send)

    @staticmethod
    async def _refuse(scope: Scope, send: Send) -> None:
        await refuse(scope, send, 403, "origin not allowed")


async def refuse(scope: Scope, send: Send, status: int, reason: str) -> None:
    """Answer a request this server will not serve: a WebSocket closes with 1008 and ``reason``,
    an HTTP request gets ``status`` with ``{"detail": reason}``."""
    if scope["type"] == "websocket":
        await send({"type": "websocket.close", "code": 1008, "reason": reason})
        return
    body = json.dumps({"detail": reason}, separators=(",", ":")).encode()
    await send(
        {
            "type": "http.response.start",
            "status": status,
            "headers": [
                (b"content-type", b"application/json"),
                (b"content-length", str(len(body)).encode()),
            ],
        }
    )
    await send({"type": "http.response.body", "body": body})
