"""How every part builds the server's URLs: base URL checks, WebSocket endpoints, role pages."""

from __future__ import annotations

import ssl
from urllib.parse import urlencode, urlsplit, urlunsplit

_WS_SCHEMES = {"http": "ws", "https": "wss", "ws": "ws", "wss": "wss"}


class ServerUrlError(ValueError):
    """A server URL that cannot be used; the message shows the expected shape."""


def server_base(server: str) -> str:
    """``server`` checked to be an ``http(s)://host[:port]`` base, without a trailing slash."""
    parts = urlsplit(server)
    if parts.scheme not in ("http", "https") or not parts.netloc:
        raise ServerUrlError(f"server URL must look like http://host:port, not {server!r}")
    return server.rstrip("/")


def ws_endpoint(server: str, path: str = "/ws") -> str:
    """The WebSocket endpoint ``path`` of a server given as ``http(s)://`` or ``ws(s)://`` URL.

    A URL that already ends with ``path`` is kept as it is (only the scheme changes).
    """
    parts = urlsplit(server)
    scheme = _WS_SCHEMES.get(parts.scheme)
    if scheme is None or not parts.netloc:
        raise ServerUrlError(f"server URL must look like http://host:port, not {server!r}")
    full = parts.path.rstrip("/")
    if not full.endswith(path):
        full += path
    return urlunsplit((scheme, parts.netloc, full, parts.query, ""))


def page_url(server: str, role: str, room: str, **query: str | int) -> str:
    """A role page of ``room`` (``/vehicle``, ``/relay``, ``/client``, ...) with extra query."""
    return f"{server_base(server)}/{role}?{urlencode({'room': room, **query})}"


def reachable_host(host: str) -> str:
    """The address to put in a URL for a server bound to ``host`` (wildcards mean loopback)."""
    return "127.0.0.1" if host in ("0.0.0.0", "::", "") else host


def untrusted_hint(exc: BaseException) -> str:
    """What to do when ``exc`` (or its reason) is a certificate the client does not trust; ""
    for any other error."""
    reason = getattr(exc, "reason", None)
    if isinstance(exc, ssl.SSLCertVerificationError) or isinstance(
        reason, ssl.SSLCertVerificationError
    ):
        return (
            "; the server's certificate is not trusted here: pass --ca-file with its CA"
            " (autopilot serve --self-signed prints where its ca.pem is)"
        )
    return ""
