"""What a person sees on the first day on a second machine (issue 23): every message says what
to do next. CLI output as printed, by the real commands."""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.cli import main
from app.server import tls
from app.server.serve import RunningServer
from tests.test_cli_errors import assert_one_line_error, autopilot, in_process

SECRET = "a-first-day-secret-of-enough-length"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def serve_output(*args: str, env: dict[str, str], until: str, timeout: float = 60) -> str:
    """Run ``autopilot serve`` until its log shows ``until``, then stop it; its log."""
    # The environment the tests run in, without a secret unless ``env`` gives one.
    base = {k: v for k, v in os.environ.items() if k != "AUTOPILOT_SECRET"}
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", *args],
        env={**base, **env},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    lines: list[str] = []
    try:
        assert server.stderr is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            line = server.stderr.readline()
            if not line:
                break
            lines.append(line)
            if until in line:
                break
    finally:
        server.terminate()
        server.wait(timeout=10)
        if server.stderr is not None:
            server.stderr.close()
    output = "".join(lines)
    assert until in output, output
    return output


# The token command and the help texts run in this process: nothing starts, nothing listens.
def test_token_without_a_secret_says_how_to_make_one(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    monkeypatch.setenv("AUTOPILOT_SECRET", "")
    _, line = in_process(capsys, caplog, "token", "--room", "lab", "--role", "client")
    assert "AUTOPILOT_SECRET is not set" in line and "secrets.token_urlsafe(32)" in line, line


def test_token_says_which_server_it_assumed_from_the_server_s_settings(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    caplog: pytest.LogCaptureFixture,
) -> None:
    monkeypatch.setenv("AUTOPILOT_SECRET", SECRET)
    monkeypatch.setenv("AUTOPILOT_PORT", "8123")
    caplog.set_level(logging.INFO)
    assert main(["token", "--room", "lab", "--role", "client"]) == 0, caplog.text
    assert "assuming http://127.0.0.1:8123" in caplog.text
    assert '"url": "http://127.0.0.1:8123/client?room=lab#token=' in capsys.readouterr().out


@pytest.mark.parametrize(
    ("command", "words"),
    [
        ("token", "AUTOPILOT_SECRET"),
        ("lab", "needs root"),
        ("demo", "turns on HTTPS"),
    ],
)
def test_help_says_what_a_command_needs(
    capsys: pytest.CaptureFixture[str], command: str, words: str
) -> None:
    with pytest.raises(SystemExit) as exited:
        main([command, "--help"])
    out = capsys.readouterr().out
    assert exited.value.code == 0 and words in " ".join(out.split()), out


def test_serve_on_a_port_in_use_is_one_line_before_any_url(server: RunningServer) -> None:
    port = server.url.rsplit(":", 1)[1]
    result = autopilot("serve", "--port", port)
    assert_one_line_error(result, f"port {port}", "already in use", "--port")
    assert "page:" not in result.stderr


def test_serve_on_every_address_lists_them_and_warns_without_a_secret() -> None:
    port = str(free_port())
    output = serve_output("--host", "0.0.0.0", "--port", port, env={}, until="anyone on")
    _, addresses = tls.machine_names()
    for address in addresses:
        if address.version == 4:
            assert f"http://{address}:{port}" in output, output
    assert "anyone on the network can drive" in output


def test_serve_with_a_secret_says_how_to_mint_a_token() -> None:
    port = str(free_port())
    output = serve_output("--port", port, env={"AUTOPILOT_SECRET": SECRET}, until="token")
    assert f"autopilot token --room default --role client --server http://127.0.0.1:{port}" in (
        output
    )


def test_self_signed_trust_text_once_with_the_headless_flag(tmp_path: Path) -> None:
    port = str(free_port())
    output = serve_output(
        "--port", port, "--self-signed", "--state-dir", str(tmp_path), env={}, until="client page"
    )
    assert output.count("To trust this server") == 1, output
    spki = tls.spki_sha256(tmp_path / "ca.pem")
    assert f"--ignore-certificate-errors-spki-list={spki}" in output
    assert "libnss3-tools" in output


def test_an_untrusted_certificate_suggests_ca_file(tmp_path: Path) -> None:
    port = str(free_port())
    server = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", "--port", port, "--self-signed"]
        + ["--state-dir", str(tmp_path)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with socket.socket() as probe:
                if probe.connect_ex(("127.0.0.1", int(port))) == 0:
                    break
            time.sleep(0.2)
        result = autopilot("relay", "--server", f"https://127.0.0.1:{port}")
        assert_one_line_error(result, "not trusted", "--ca-file")
    finally:
        server.terminate()
        server.wait(timeout=10)
