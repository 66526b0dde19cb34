"""Issue 9 against a real server: foreign origins refused before accept, tokens on /rosbridge
and /turtlesim/state, security headers, no /docs in production, tokens out of page configs."""

from __future__ import annotations

import asyncio
import json
import time
from collections.abc import Callable
from html.parser import HTMLParser
from typing import Any

import httpx
import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from app.protocol import tokens
from app.server.config import Settings
from app.server.serve import RunningServer
from app.server.tls import ROSBRIDGE_TLS_FIX
from tests.helpers.sockets import Records
from tests.server.test_pages import embedded_config

SECRET = "guarded-endpoints-test-secret"
EVIL = "http://evil.example"
RECV_S = 5.0


def _token(role: tokens.Role, room: str = "lab") -> str:
    return tokens.sign(SECRET, room, role, now=time.time(), ttl_s=300)


@pytest.fixture
def guarded(start_server: Callable[[Settings], RunningServer]) -> RunningServer:
    return start_server(Settings(environment="development", secret=SECRET))


def _ws(server: RunningServer, path: str) -> str:
    return server.url.replace("http", "ws", 1) + path


async def _recv(ws: ClientConnection) -> dict[str, Any]:
    message: dict[str, Any] = json.loads(await asyncio.wait_for(ws.recv(), RECV_S))
    return message


async def _call(ws: ClientConnection, service: str, **args: Any) -> dict[str, Any]:
    await ws.send(json.dumps({"op": "call_service", "id": "s", "service": service, "args": args}))
    return await _recv(ws)


# -- origins ------------------------------------------------------------------------------------


@pytest.mark.parametrize("path", ["/ws", "/rosbridge"])
async def test_a_cross_site_handshake_is_refused_with_403(server: RunningServer, path: str) -> None:
    # Issue 9: a socket opened with Origin: http://evil.example logged in and drove the turtle.
    with pytest.raises(InvalidStatus) as refused:
        async with connect(_ws(server, path), origin=EVIL):  # type: ignore[arg-type]
            pass
    assert refused.value.response.status_code == 403


@pytest.mark.parametrize("path", ["/ws", "/rosbridge"])
async def test_own_listed_and_tool_origins_are_admitted(
    start_server: Callable[[Settings], RunningServer], path: str
) -> None:
    server = start_server(Settings(allowed_origins=["https://console.example"]))
    for origin in (server.url, "https://console.example", None):
        async with connect(_ws(server, path), origin=origin) as ws:  # type: ignore[arg-type]
            await ws.ping()


def test_a_cross_site_state_changing_request_is_refused(server: RunningServer) -> None:
    response = httpx.post(server.url + "/healthz", headers={"Origin": EVIL}, timeout=10)
    assert response.status_code == 403 and response.json() == {"detail": "origin not allowed"}
    # The same request from the server's own page reaches the app (which has no POST here).
    assert httpx.post(server.url + "/healthz", headers={"Origin": server.url}).status_code == 405


# -- tokens on /rosbridge and /turtlesim/state ----------------------------------------------------


async def test_rosbridge_without_a_token_answers_nothing_and_closes(guarded: RunningServer) -> None:
    # Issue 9: /rosbridge answered without any token, even in production mode.
    async with connect(_ws(guarded, "/rosbridge")) as ws:
        reply = await _call(ws, "/kill", name="turtle1")
        assert reply["op"] == "status" and "authenticate first" in reply["msg"]
        with pytest.raises(ConnectionClosed):
            await _recv(ws)
        assert ws.close_code == 1008
    state = httpx.get(guarded.url + "/turtlesim/state", timeout=10)
    assert state.status_code == 401
    assert [t["name"] for t in _state(guarded)["turtles"]] == ["turtle1"]


@pytest.mark.parametrize("role", ["relay", "client"])
async def test_a_reader_token_may_watch_but_not_drive(guarded: RunningServer, role: str) -> None:
    async with connect(_ws(guarded, "/rosbridge")) as ws:
        await ws.send(json.dumps({"op": "auth", "token": _token(role)}))  # type: ignore[arg-type]
        await ws.send(json.dumps({"op": "subscribe", "topic": "/turtle1/pose"}))
        assert (await _recv(ws))["topic"] == "/turtle1/pose"
        for service, args in [
            ("/kill", {"name": "turtle1"}),
            ("/reset", {}),
            ("/turtle1/teleport_absolute", {"x": 1.0, "y": 1.0, "theta": 0.0}),
        ]:
            await ws.send(json.dumps({"op": "unsubscribe", "topic": "/turtle1/pose"}))
            reply = await _call(ws, service, **args)
            while reply["op"] == "publish":
                reply = await _recv(ws)
            assert reply["op"] == "status" and "needs a vehicle token" in reply["msg"]
    turtle = _state(guarded)["turtles"][0]
    assert turtle["name"] == "turtle1" and turtle["x"] != 1.0


async def test_a_vehicle_token_drives_by_auth_op_or_header(guarded: RunningServer) -> None:
    async with connect(_ws(guarded, "/rosbridge")) as ws:
        await ws.send(json.dumps({"op": "auth", "token": _token("vehicle")}))
        reply = await _call(ws, "/turtle1/teleport_absolute", x=2.0, y=3.0, theta=0.0)
        assert reply["op"] == "service_response" and reply["result"] is True
    assert (_state(guarded)["turtles"][0]["x"], _state(guarded)["turtles"][0]["y"]) == (2.0, 3.0)
    header = {"Authorization": f"Bearer {_token('vehicle', room='other')}"}
    async with connect(_ws(guarded, "/rosbridge"), additional_headers=header) as ws:
        reply = await _call(ws, "/turtle1/teleport_absolute", x=4.0, y=3.0, theta=0.0)
        assert reply["op"] == "service_response" and reply["result"] is True
    assert _state(guarded)["turtles"][0]["x"] == 4.0


async def test_a_bad_header_token_is_refused_before_accept(guarded: RunningServer) -> None:
    stale = tokens.sign(SECRET, "lab", "vehicle", now=time.time() - 600, ttl_s=60)
    with pytest.raises(InvalidStatus) as refused:
        async with connect(
            _ws(guarded, "/rosbridge"), additional_headers={"Authorization": f"Bearer {stale}"}
        ):
            pass
    assert refused.value.response.status_code == 403


BACKGROUND_R = "/turtlesim:background_r"  # turtlesim's parameter, as ROS 2 names it (69)


@pytest.mark.parametrize("role", ["client", "relay"])
async def test_a_reader_token_of_another_room_sets_no_parameter(
    guarded: RunningServer, role: tokens.Role
) -> None:
    # Issue 37.3: /rosapi/set_param succeeded with a client token of another room.
    async with connect(_ws(guarded, "/rosbridge")) as ws:
        await ws.send(json.dumps({"op": "auth", "token": _token(role, room="elsewhere")}))
        for service in ("/rosapi/set_param", "rosapi/set_param"):
            reply = await _call(ws, service, name=BACKGROUND_R, value="7")
            assert reply["op"] == "status" and "needs a vehicle token" in reply["msg"]
        reply = await _call(ws, "/rosapi/get_param", name=BACKGROUND_R)
        assert reply["result"] is True and json.loads(reply["values"]["value"]) == 69
    async with connect(_ws(guarded, "/rosbridge")) as ws:  # a vehicle token still may
        await ws.send(json.dumps({"op": "auth", "token": _token("vehicle")}))
        reply = await _call(ws, "/rosapi/set_param", name=BACKGROUND_R, value="7")
        assert reply["result"] is True and reply["values"]["successful"] is True
        reply = await _call(ws, "/rosapi/get_param", name=BACKGROUND_R)
        assert json.loads(reply["values"]["value"]) == 7


@pytest.mark.parametrize("role", ["client", "relay", "vehicle"])
async def test_frames_whose_op_is_not_a_string_get_a_status_and_the_connection_lives(
    guarded: RunningServer, server_log: Records, role: tokens.Role
) -> None:
    # Issue 37.2: with a client token, 200 frames whose op was a list or an object gave 200
    # tracebacks and each killed its connection's reader.
    async with connect(_ws(guarded, "/rosbridge")) as ws:
        await ws.send(json.dumps({"op": "auth", "token": _token(role)}))
        for op in [["publish"], {"op": "publish"}, [], {}, 7, None, True]:
            await ws.send(json.dumps({"op": op, "id": "bad", "topic": "/turtle1/cmd_vel"}))
            reply = await _recv(ws)
            assert reply == {
                "op": "status",
                "level": "error",
                "msg": "message has no string 'op' field",
                "id": "bad",
            }
        reply = await _call(ws, "/rosapi/topics")
        assert reply["op"] == "service_response" and reply["result"] is True
    assert server_log.tracebacks() == []


async def test_a_room_token_sees_its_own_room_and_only_a_fleet_token_sees_them_all(
    guarded: RunningServer,
) -> None:
    # Issue 37.7: /fleet/rooms with a client token for room B listed room A's vehicle name.
    async with connect(_ws(guarded, "/ws")) as a, connect(_ws(guarded, "/ws")) as b:
        for ws, name, role, room in ((a, "robot-of-a", "vehicle", "a"), (b, "bob", "client", "b")):
            token = _token(role, room=room)  # type: ignore[arg-type]
            await ws.send(
                json.dumps(
                    {"type": "login", "name": name, "role": role, "room": room, "token": token}
                )
            )
            assert (await _recv(ws))["success"] is True

        def rooms(token: str) -> httpx.Response:
            headers = {"Authorization": f"Bearer {token}"}
            return httpx.get(guarded.url + "/fleet/rooms", headers=headers, timeout=10)

        for role in ("client", "relay", "vehicle"):
            seen = rooms(_token(role, room="b"))  # type: ignore[arg-type]
            assert seen.status_code == 200, seen.text
            assert [row["room"] for row in seen.json()] == ["b"]
            assert "robot-of-a" not in seen.text
        assert rooms(_token("client", room="nowhere")).json() == []
        fleet = rooms(tokens.sign(SECRET, tokens.ALL_ROOMS, "fleet", now=time.time(), ttl_s=60))
        assert [(row["room"], row["vehicles"]) for row in fleet.json()] == [
            ("a", ["robot-of-a"]),
            ("b", []),
        ]
        assert rooms("not.a-token").status_code == 401


async def test_a_fleet_token_opens_nothing_but_the_fleet_view(guarded: RunningServer) -> None:
    fleet = tokens.sign(SECRET, tokens.ALL_ROOMS, "fleet", now=time.time(), ttl_s=60)
    async with connect(_ws(guarded, "/ws")) as ws:
        login = {"type": "login", "name": "f", "role": "client", "room": "*", "token": fleet}
        await ws.send(json.dumps(login))
        reply = await _recv(ws)
        assert reply["success"] is False and "wrong role" in reply["reason"]
    async with connect(_ws(guarded, "/rosbridge")) as ws:
        await ws.send(json.dumps({"op": "auth", "token": fleet}))
        assert "wrong role" in (await _recv(ws))["msg"]
        with pytest.raises(ConnectionClosed):
            await _recv(ws)
    headers = {"Authorization": f"Bearer {fleet}"}
    state = httpx.get(guarded.url + "/turtlesim/state", headers=headers, timeout=10)
    assert state.status_code == 401


def _state(server: RunningServer) -> dict[str, Any]:
    headers = {"Authorization": f"Bearer {_token('client', room='anywhere')}"}
    response = httpx.get(server.url + "/turtlesim/state", headers=headers, timeout=10)
    assert response.status_code == 200, response.text
    state: dict[str, Any] = response.json()
    return state


# -- headers, docs, pages -------------------------------------------------------------------------


class _Scripts(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.inline: list[dict[str, str | None]] = []
        self.handlers: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        named = dict(attrs)
        self.handlers += [k for k in named if k.startswith("on")]
        if tag == "script" and "src" not in named and named.get("type") != "application/json":
            self.inline.append(named)


@pytest.mark.parametrize(
    "path", ["/", "/vehicle", "/relay", "/client", "/parity", "/static/js/net/room.js", "/healthz"]
)
def test_every_response_carries_the_security_headers(server: RunningServer, path: str) -> None:
    response = httpx.get(server.url + path, timeout=10)
    assert response.status_code == 200
    policy = response.headers["content-security-policy"]
    directives = dict(d.strip().split(" ", 1) for d in policy.split(";"))
    assert directives["script-src"] == "'self'"
    assert directives["frame-ancestors"] == "'none'"
    assert "unsafe-inline" not in policy and "unsafe-eval" not in policy
    assert response.headers["x-content-type-options"] == "nosniff"
    if path in ("/", "/vehicle", "/relay", "/client", "/parity"):
        scripts = _Scripts()
        scripts.feed(response.text)
        assert scripts.inline == [] and scripts.handlers == []


def test_docs_are_off_in_production(start_server: Callable[[Settings], RunningServer]) -> None:
    production = start_server(Settings(environment="production", secret=SECRET))
    for path in ("/docs", "/redoc", "/openapi.json"):
        assert httpx.get(production.url + path, timeout=10).status_code == 404
    assert httpx.get(production.url + "/healthz", timeout=10).status_code == 200


def test_a_token_in_the_query_string_does_not_reach_the_page(server: RunningServer) -> None:
    # Tokens travel in the fragment; one put in the query is not echoed into the page.
    html = httpx.get(server.url + "/client?room=r&token=SECRET-ISH", timeout=10).text
    assert "SECRET-ISH" not in html
    assert "token" not in embedded_config(html)


@pytest.mark.parametrize(
    ("rosbridge", "refused"),
    [
        (None, False),
        ("ws://localhost:9090", False),
        ("ws://127.0.0.1:9090", False),
        ("wss://robot.lan:9090", False),
        ("ws://robot.lan:9090", True),
    ],
)
def test_https_pages_refuse_a_remote_ws_rosbridge(
    server: RunningServer, rosbridge: str | None, refused: bool
) -> None:
    query = "" if rosbridge is None else f"?rosbridge={rosbridge}"
    # The page as if reached over HTTPS (a TLS-terminating proxy passing the scheme on).
    config = embedded_config(
        httpx.get(
            server.url + "/vehicle" + query, headers={"X-Forwarded-Proto": "https"}, timeout=10
        ).text
    )
    assert config["rosbridgeAuth"] is (rosbridge is None)
    error = config["rosbridgeError"]
    if refused:
        assert error is not None and ROSBRIDGE_TLS_FIX in error and "ssl:=true" in error
    else:
        assert error is None
