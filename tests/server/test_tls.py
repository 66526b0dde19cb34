"""``--self-signed``: a local CA and server certificate, made once, kept, and really usable."""

from __future__ import annotations

import ipaddress
import json
import os
import ssl
import stat
import subprocess
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from cryptography import x509

from app.server import tls
from app.server.config import Settings
from app.server.serve import start_in_thread

LOOPBACK = [ipaddress.ip_address("127.0.0.1"), ipaddress.ip_address("::1")]


def _san(certfile: Path) -> x509.SubjectAlternativeName:
    cert = x509.load_pem_x509_certificate(certfile.read_bytes())
    return cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value


def test_made_once_then_reused(tmp_path: Path) -> None:
    first = tls.self_signed(tmp_path, ["localhost"], LOOPBACK)
    assert first.ca_file is not None
    stored = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    assert set(stored) == {"ca.pem", "ca-key.pem", "server.pem", "server-key.pem"}
    for key in ("ca-key.pem", "server-key.pem"):
        assert stat.S_IMODE((tmp_path / key).stat().st_mode) == 0o600
    again = tls.self_signed(tmp_path, ["localhost"], LOOPBACK)
    assert again == first
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == stored


def test_a_new_address_gets_a_new_server_certificate_from_the_same_ca(tmp_path: Path) -> None:
    tls.self_signed(tmp_path, ["localhost"], LOOPBACK)
    ca_before = (tmp_path / "ca.pem").read_bytes()
    moved = [*LOOPBACK, ipaddress.ip_address("10.203.0.1")]
    tls.self_signed(tmp_path, ["localhost", "robot"], moved)
    assert (tmp_path / "ca.pem").read_bytes() == ca_before
    san = _san(tmp_path / "server.pem")
    assert ipaddress.ip_address("10.203.0.1") in san.get_values_for_type(x509.IPAddress)
    assert "robot" in san.get_values_for_type(x509.DNSName)


def test_the_machine_names_cover_loopback_and_every_interface() -> None:
    names, addresses = tls.machine_names()
    assert "localhost" in names
    assert ipaddress.ip_address("127.0.0.1") in addresses
    assert all(not a.is_link_local for a in addresses)


def test_trust_instructions_name_the_file_and_its_fingerprint(tmp_path: Path) -> None:
    files = tls.self_signed(tmp_path, ["localhost"], LOOPBACK)
    assert files.ca_file is not None
    text = tls.trust_instructions(files.ca_file)
    cert = x509.load_pem_x509_certificate(files.ca_file.read_bytes())
    assert str(files.ca_file) in text and "--ca-file" in text
    assert cert.fingerprint(cert.signature_hash_algorithm).hex(":").upper() in text  # type: ignore[arg-type]


def certutil(*args: str) -> str:
    """What NSS's ``certutil`` prints with ``args``."""
    done = subprocess.run(
        ["certutil", *args],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    return done.stdout


def test_the_printed_chromium_line_trusts_the_ca_where_chromium_never_ran(tmp_path: Path) -> None:
    files = tls.self_signed(tmp_path / "state dir", ["localhost"], LOOPBACK)
    assert files.ca_file is not None
    text = tls.trust_instructions(files.ca_file)
    [line] = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("mkdir -p")]
    home = tmp_path / "home"  # a user whose Chromium never ran: no ~/.pki at all
    home.mkdir()
    env = {**os.environ, "HOME": str(home)}
    nssdb = f"sql:{home}/.pki/nssdb"
    # Twice: the second time the database exists, as it does once Chromium has run.
    for _ in range(2):
        run = subprocess.run(
            ["bash", "-c", line],
            env=env,
            stdin=subprocess.DEVNULL,
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert run.returncode == 0, run.stdout + run.stderr
        listed = certutil("-d", nssdb, "-L")
        assert ["webrtc-autopilot", "C,,"] in [row.split() for row in listed.splitlines()], listed
    exported = certutil("-d", nssdb, "-L", "-n", "webrtc-autopilot", "-a")
    imported = x509.load_pem_x509_certificate(exported.encode())
    assert imported == x509.load_pem_x509_certificate(files.ca_file.read_bytes())


@pytest.mark.parametrize("host_name", ["127.0.0.1", "localhost"])
def test_a_client_trusting_the_ca_verifies_the_server(tmp_path: Path, host_name: str) -> None:
    files = tls.self_signed(tmp_path)
    server = start_in_thread(Settings(environment="development", token=None), tls_files=files)
    try:
        assert server.url.startswith("https://")
        port = server.url.rsplit(":", 1)[1]
        context = ssl.create_default_context(cafile=str(files.ca_file))
        with urllib.request.urlopen(
            f"https://{host_name}:{port}/healthz", context=context, timeout=10
        ) as response:
            assert json.load(response) == {"status": "ok"}
        # Without the CA the same request is refused: the certificate is not publicly trusted.
        with pytest.raises(urllib.error.URLError, match="CERTIFICATE_VERIFY_FAILED"):
            urllib.request.urlopen(
                f"https://{host_name}:{port}/healthz",
                context=ssl.create_default_context(),
                timeout=10,
            )
    finally:
        server.stop()
