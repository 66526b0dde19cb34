"""The agent's signaling client: URL handling, and login against the real /ws."""

from __future__ import annotations

import pytest

from app.server.serve import RunningServer
from vehicle_agent.signaling import LoginRefused, SignalingClient, SignalingError, ws_url


@pytest.mark.parametrize(
    ("server", "expected"),
    [
        ("http://127.0.0.1:8000", "ws://127.0.0.1:8000/ws"),
        ("http://robot.local:8000/", "ws://robot.local:8000/ws"),
        ("https://example.org/autopilot", "wss://example.org/autopilot/ws"),
        ("ws://127.0.0.1:8000/ws", "ws://127.0.0.1:8000/ws"),
    ],
)
def test_ws_url(server: str, expected: str) -> None:
    assert ws_url(server) == expected


@pytest.mark.parametrize("server", ["127.0.0.1:8000", "ftp://host/", "http://"])
def test_ws_url_refuses_what_is_not_a_server_url(server: str) -> None:
    with pytest.raises(SignalingError, match="server URL"):
        ws_url(server)


async def test_login_returns_the_roster(server: RunningServer) -> None:
    first = SignalingClient(server.url, "r1", "room-a", role="relay")
    assert await first.connect() == []
    second = SignalingClient(server.url, "v1", "room-a")
    try:
        assert await second.connect() == [{"name": "r1", "role": "relay"}]
    finally:
        await second.close()
        await first.close()


async def test_refused_login_says_why(server: RunningServer) -> None:
    first = SignalingClient(server.url, "taken", "room-b")
    await first.connect()
    try:
        with pytest.raises(LoginRefused, match="login refused"):
            await SignalingClient(server.url, "taken", "room-b").connect()
    finally:
        await first.close()


async def test_a_server_without_ws_is_named(server: RunningServer) -> None:
    with pytest.raises(SignalingError, match=r"cannot reach signaling server at .*/nothing/ws"):
        await SignalingClient(server.url + "/nothing", "v", "r").connect()
