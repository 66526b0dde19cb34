"""``autopilot token``: its last line is ``{"token", "url"}``, the token in the URL fragment."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from urllib.parse import parse_qs, urlsplit

from app.protocol import tokens

SECRET = "token-command-test-secret"


def _token(*args: str, secret: str | None = SECRET) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "AUTOPILOT_SECRET"}
    if secret is not None:
        env["AUTOPILOT_SECRET"] = secret
    return subprocess.run(
        [sys.executable, "-m", "app.cli", "token", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_output_shape_and_a_token_the_server_accepts() -> None:
    result = _token(
        "--room", "lab 1", "--role", "relay", "--ttl", "120", "--server", "https://10.203.0.1:8443/"
    )
    assert result.returncode == 0, result.stderr
    last = json.loads(result.stdout.strip().splitlines()[-1])
    assert set(last) == {"token", "url"}
    url = urlsplit(last["url"])
    assert (url.scheme, url.netloc, url.path) == ("https", "10.203.0.1:8443", "/relay")
    assert parse_qs(url.query) == {"room": ["lab 1"]}
    assert url.fragment == f"token={last['token']}"
    assert last["token"] not in url.query
    claims = tokens.verify(SECRET, last["token"], now=time.time(), room="lab 1", roles=("relay",))
    assert claims.exp <= time.time() + 121


def test_no_secret_is_one_line_and_exit_1() -> None:
    result = _token("--room", "lab", "--role", "client", secret=None)
    assert result.returncode == 1
    assert result.stdout == ""
    assert "AUTOPILOT_SECRET is not set" in result.stderr
    assert "Traceback" not in result.stderr


def test_unknown_role_is_refused_by_the_parser() -> None:
    result = _token("--room", "lab", "--role", "admin")
    assert result.returncode == 2
    assert "invalid choice" in result.stderr


def test_a_fleet_token_is_for_the_fleet_page_of_every_room_and_nothing_else() -> None:
    result = _token("--role", "fleet", "--server", "http://10.0.0.5:8000")
    assert result.returncode == 0, result.stderr
    last = json.loads(result.stdout.strip().splitlines()[-1])
    assert last["url"] == f"http://10.0.0.5:8000/fleet#token={last['token']}"
    claims = tokens.verify(SECRET, last["token"], now=time.time(), roles=("fleet",))
    assert claims.room == tokens.ALL_ROOMS
    # A room's roles only, unless fleet is asked for: it logs in nowhere, drives nothing.
    refused = None
    try:
        tokens.verify(SECRET, last["token"], now=time.time())
    except tokens.TokenError as exc:
        refused = exc.reason
    assert refused == "wrong role"
    both = _token("--role", "fleet", "--room", "lab")
    assert both.returncode == 1 and "leave out --room" in both.stderr
    neither = _token("--role", "client")
    assert neither.returncode == 1 and "--room is required" in neither.stderr
