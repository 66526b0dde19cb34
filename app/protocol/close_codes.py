"""WebSocket close codes (RFC 6455 §7.4.1) the server's sockets close with."""

from __future__ import annotations

from enum import IntEnum


class CloseCode(IntEnum):
    """A close code of ``/ws`` and ``/rosbridge`` (docs/contracts.md, "WebSocket policy")."""

    NORMAL = 1000
    POLICY_VIOLATION = 1008
    TRY_AGAIN_LATER = 1013
