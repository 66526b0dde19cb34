"""Security headers on every HTTP response: a Content-Security-Policy with no inline script,
no framing, no MIME sniffing, no referrer.

The pages run only same-origin ES modules; their configuration is a ``application/json`` block,
which is data and never executed. OpenCV.js, which the relay's vision worker loads, compiles
WebAssembly and builds its bindings with ``new Function``, so the worker script alone is served
with ``'unsafe-eval' 'wasm-unsafe-eval'``; a dedicated worker takes the policy of its own
response, so the pages never get either.
"""

from __future__ import annotations

from starlette.datastructures import MutableHeaders
from starlette.types import ASGIApp, Message, Receive, Scope, Send

# The vehicle page may talk to a rosbridge on another host (ws://localhost:9090 on the robot, or
# wss://robot:9090), so WebSocket connections are not limited to this origin.
_PAGE_POLICY = {
    "default-src": "'self'",
    "script-src": "'self'",
    "style-src": "'self'",
    "img-src": "'self' data: blob:",
    "media-src": "'self' blob: mediastream:",
    "connect-src": "'self' ws: wss:",
    "worker-src": "'self'",
    "object-src": "'none'",
    "base-uri": "'none'",
    "form-action": "'self'",
    "frame-ancestors": "'none'",
}
PAGE_POLICY = "; ".join(f"{k} {v}" for k, v in _PAGE_POLICY.items())
WORKER_POLICY = "; ".join(
    f"{k} {v}"
    for k, v in {
        **_PAGE_POLICY,
        "script-src": "'self' 'unsafe-eval' 'wasm-unsafe-eval'",
    }.items()
)
# Scripts that run as the vision worker (and what it imports with importScripts()).
WORKER_PATHS = frozenset({"/static/js/worker/vision-worker.js"})

COMMON_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Opener-Policy": "same-origin",
}


class SecurityHeaders:
    """ASGI middleware adding the headers above to every HTTP response it passes on."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Pass the request on; add the headers to the response start."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        policy = WORKER_POLICY if scope["path"] in WORKER_PATHS else PAGE_POLICY

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                headers["Content-Security-Policy"] = policy
                for name, value in COMMON_HEADERS.items():
                    headers[name] = value
            await send(message)

        await self.app(scope, receive, send_with_headers)
