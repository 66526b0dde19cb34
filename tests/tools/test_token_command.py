"""``autopilot token``: its last line is ``{"token", "url"}``, the token in the URL fragment."""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import time
from collections.abc import Callable
from urllib.parse import parse_qs, urlsplit

import pytest

from app.cli import main
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


Token = Callable[..., tuple[int, str, str]]


@pytest.fixture
def token(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> Token:
    """``autopilot token args`` in this process (nothing starts): its status, stdout and what
    it logged (the parser's refusal on stderr included)."""
    caplog.set_level(logging.INFO)

    def run(*args: str, secret: str | None = SECRET) -> tuple[int, str, str]:
        if secret is None:
            monkeypatch.delenv("AUTOPILOT_SECRET", raising=False)
        else:
            monkeypatch.setenv("AUTOPILOT_SECRET", secret)
        caplog.clear()
        try:
            status = main(["token", *args])
        except SystemExit as exited:
            status = exited.code if isinstance(exited.code, int) else 1
        out, err = capsys.readouterr()
        return status, out, err + caplog.text

    return run


def test_output_shape_and_a_token_the_server_accepts() -> None:
    # The whole process: its last line on stdout is what scripts read.
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


def test_no_secret_is_one_line_and_exit_1(token: Token) -> None:
    status, out, said = token("--room", "lab", "--role", "client", secret=None)
    assert status == 1
    assert out == ""
    assert "AUTOPILOT_SECRET is not set" in said
    assert "Traceback" not in said


def test_unknown_role_is_refused_by_the_parser(token: Token) -> None:
    status, _, said = token("--room", "lab", "--role", "admin")
    assert status == 2
    assert "invalid choice" in said


def test_a_fleet_token_is_for_the_fleet_page_of_every_room_and_nothing_else(token: Token) -> None:
    status, out, said = token("--role", "fleet", "--server", "http://10.0.0.5:8000")
    assert status == 0, said
    last = json.loads(out.strip().splitlines()[-1])
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
    status, _, said = token("--role", "fleet", "--room", "lab")
    assert status == 1 and "leave out --room" in said
    status, _, said = token("--role", "client")
    assert status == 1 and "--room is required" in said
