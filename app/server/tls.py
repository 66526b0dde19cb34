"""HTTPS for the server: an operator's own certificate, or a local CA made on first use.

``--self-signed`` keeps a private CA and a server certificate under the state directory
(``$XDG_DATA_HOME/webrtc-autopilot``, normally ``~/.local/share/webrtc-autopilot``). The CA is
made once, so a browser or robot that trusts it keeps trusting the server; the server
certificate is issued again whenever this machine's names or addresses change or it nears its
end. Private keys are written readable by their owner only.
"""

from __future__ import annotations

import argparse
import base64
import datetime
import hashlib
import ipaddress
import logging
import os
import shlex
import socket
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit

import ifaddr
from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

log = logging.getLogger(__name__)

APP_DIR_NAME = "webrtc-autopilot"
CA_VALIDITY = datetime.timedelta(days=3650)
# Browsers refuse server certificates valid for more than 398 days, even from a private CA.
SERVER_VALIDITY = datetime.timedelta(days=397)
# A server certificate this close to its end is issued again at the next start.
RENEW_BEFORE = datetime.timedelta(days=30)

IpAddress = ipaddress.IPv4Address | ipaddress.IPv6Address


@dataclass(frozen=True)
class TlsFiles:
    """Where the certificate chain and key a server presents are, and the CA that signed them."""

    certfile: Path
    keyfile: Path
    ca_file: Path | None = None


def default_state_dir() -> Path:
    """``$XDG_DATA_HOME/webrtc-autopilot``, or ``~/.local/share/webrtc-autopilot``."""
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / APP_DIR_NAME


def machine_names() -> tuple[list[str], list[IpAddress]]:
    """This machine's DNS names and every address of its interfaces, loopback included.

    IPv6 link-local addresses are left out: a URL to one needs a zone id no certificate holds.
    """
    names = {"localhost"}
    for name in (socket.gethostname(), socket.getfqdn()):
        if name and _is_dns_name(name):
            names.add(name.lower())
    addresses: set[IpAddress] = {ipaddress.ip_address("127.0.0.1"), ipaddress.ip_address("::1")}
    for adapter in ifaddr.get_adapters():
        for ip in adapter.ips:
            text = ip.ip if isinstance(ip.ip, str) else ip.ip[0]
            address = ipaddress.ip_address(text)
            if not address.is_link_local:
                addresses.add(address)
    return sorted(names), sorted(addresses, key=lambda a: (a.version, int(a)))


def self_signed(
    state_dir: Path | None = None,
    names: list[str] | None = None,
    addresses: list[IpAddress] | None = None,
    now: datetime.datetime | None = None,
) -> TlsFiles:
    """The CA and server certificate under ``state_dir``, made or renewed as needed.

    ``names``/``addresses`` default to :func:`machine_names`. Logs how to trust the CA whenever
    it is created.
    """
    state_dir = state_dir or default_state_dir()
    now = now or datetime.datetime.now(datetime.UTC)
    if names is None or addresses is None:
        found_names, found_addresses = machine_names()
        names = found_names if names is None else names
        addresses = found_addresses if addresses is None else addresses
    state_dir.mkdir(parents=True, exist_ok=True, mode=0o700)
    files = TlsFiles(
        certfile=state_dir / "server.pem",
        keyfile=state_dir / "server-key.pem",
        ca_file=state_dir / "ca.pem",
    )
    ca_key_file = state_dir / "ca-key.pem"
    assert files.ca_file is not None
    if files.ca_file.exists() and ca_key_file.exists():
        ca_cert = x509.load_pem_x509_certificate(files.ca_file.read_bytes())
        ca_key = serialization.load_pem_private_key(ca_key_file.read_bytes(), password=None)
        if not isinstance(ca_key, ec.EllipticCurvePrivateKey):
            raise ValueError(f"{ca_key_file} is not the EC key this tool writes")
    else:
        ca_cert, ca_key = _make_ca(now)
        _write_key(ca_key_file, ca_key)
        files.ca_file.write_bytes(ca_cert.public_bytes(serialization.Encoding.PEM))
        # How to trust it is said once, by whoever serves with it (from_arguments).
        log.info("created a local certificate authority at %s", files.ca_file)
    if _needs_issue(files.certfile, ca_cert, names, addresses, now):
        cert, key = _issue(ca_cert, ca_key, names, addresses, now)
        _write_key(files.keyfile, key)
        # The CA goes with it: clients pinning the CA's key (Chromium's
        # --ignore-certificate-errors-spki-list) see it only if the server presents it.
        files.certfile.write_bytes(
            cert.public_bytes(serialization.Encoding.PEM)
            + ca_cert.public_bytes(serialization.Encoding.PEM)
        )
        log.info(
            "issued a server certificate for %s",
            ", ".join([*names, *(str(a) for a in addresses)]),
        )
    return files


def trust_instructions(ca_file: Path) -> str:
    """How to make a browser, a phone or Python trust the CA in ``ca_file``."""
    cert = x509.load_pem_x509_certificate(ca_file.read_bytes())
    fingerprint = cert.fingerprint(hashes.SHA256()).hex(":").upper()
    return (
        f"To trust this server, import its CA certificate {ca_file} "
        f"(SHA-256 {fingerprint}) on each machine that opens a page:\n"
        f"  Chromium/Chrome on Linux (certutil: Debian's libnss3-tools):\n"
        f"    {chromium_trust_command(ca_file)}\n"
        f"  headless Chromium (chromium --headless, Playwright's launch args): "
        f"--ignore-certificate-errors-spki-list={spki_sha256(ca_file)}\n"
        f"  Firefox: Settings > Privacy & Security > Certificates > View Certificates > "
        f"Authorities > Import\n"
        f"  Debian/Ubuntu system-wide: sudo cp {ca_file} "
        f"/usr/local/share/ca-certificates/webrtc-autopilot.crt && sudo update-ca-certificates\n"
        f"  macOS: sudo security add-trusted-cert -d -r trustRoot "
        f"-k /Library/Keychains/System.keychain {ca_file}\n"
        f"  Android/iOS: copy the file to the device and install it as a CA certificate\n"
        f"  autopilot vehicle / autopilot relay: --ca-file {ca_file}"
    )


def chromium_trust_command(ca_file: Path | str) -> str:
    """The shell line that makes Chromium on Linux trust ``ca_file`` for this user.

    Chromium reads its CAs from the NSS database in ``~/.pki/nssdb``, which it creates on its
    first run: on a machine where it never ran, ``certutil -A`` alone fails with
    ``SEC_ERROR_BAD_DATABASE``, so the line creates an empty database first. Only when there is
    none: ``certutil -N`` on an existing one asks for its password again and again.
    """
    db = "$HOME/.pki/nssdb"
    return (
        f"mkdir -p {db} && (test -e {db}/cert9.db || certutil -d sql:{db} -N --empty-password) "
        f"&& certutil -d sql:{db} -A -t C,, -n {APP_DIR_NAME} -i {shlex.quote(str(ca_file))}"
    )


def spki_sha256(pem_file: Path) -> str:
    """Base64 SHA-256 of the public key of the (first) certificate in ``pem_file``: the form
    Chromium's ``--ignore-certificate-errors-spki-list`` takes."""
    cert = x509.load_pem_x509_certificate(pem_file.read_bytes())
    der = cert.public_key().public_bytes(
        serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo
    )
    return base64.b64encode(hashlib.sha256(der).digest()).decode("ascii")


def _make_ca(now: datetime.datetime) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, APP_DIR_NAME),
            x509.NameAttribute(
                NameOID.COMMON_NAME, f"{APP_DIR_NAME} local CA ({socket.gethostname()})"
            ),
        ]
    )
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + CA_VALIDITY)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(_key_usage(ca=True), critical=True)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .sign(key, hashes.SHA256())
    )
    return cert, key


def _issue(
    ca_cert: x509.Certificate,
    ca_key: ec.EllipticCurvePrivateKey,
    names: list[str],
    addresses: list[IpAddress],
    now: datetime.datetime,
) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    key = ec.generate_private_key(ec.SECP256R1())
    san: list[x509.GeneralName] = [x509.DNSName(n) for n in names]
    san += [x509.IPAddress(a) for a in addresses]
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, names[0] if names else "server")])
    cert = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + SERVER_VALIDITY)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(_key_usage(ca=False), critical=True)
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
        .add_extension(x509.SubjectAlternativeName(san), critical=False)
        .add_extension(
            x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False
        )
        .sign(ca_key, hashes.SHA256())
    )
    return cert, key


def _key_usage(*, ca: bool) -> x509.KeyUsage:
    return x509.KeyUsage(
        digital_signature=not ca,
        content_commitment=False,
        key_encipherment=False,
        data_encipherment=False,
        key_agreement=False,
        key_cert_sign=ca,
        crl_sign=ca,
        encipher_only=False,
        decipher_only=False,
    )


def _needs_issue(
    certfile: Path,
    ca_cert: x509.Certificate,
    names: list[str],
    addresses: list[IpAddress],
    now: datetime.datetime,
) -> bool:
    """True when there is no server certificate, or it is not this CA's, or it does not cover
    every current name and address, or it ends within :data:`RENEW_BEFORE`."""
    if not certfile.exists() or not certfile.with_name("server-key.pem").exists():
        return True
    cert = x509.load_pem_x509_certificate(certfile.read_bytes())
    if cert.issuer != ca_cert.subject or cert.not_valid_after_utc - RENEW_BEFORE < now:
        return True
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return True
    covered_names = set(san.get_values_for_type(x509.DNSName))
    covered_addresses = set(san.get_values_for_type(x509.IPAddress))
    return not (set(names) <= covered_names and set(addresses) <= covered_addresses)


def _write_key(path: Path, key: ec.EllipticCurvePrivateKey) -> None:
    pem = key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )
    # Created owner-only from the start: no moment where another user could read it.
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as out:
        out.write(pem)
    os.chmod(path, 0o600)


def _is_dns_name(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return all(part and len(part) <= 63 for part in name.split(".")) and name.isascii()
    return False


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``--certfile``/``--keyfile``, ``--self-signed`` and ``--state-dir``, for serve and demo."""
    group = parser.add_argument_group("HTTPS")
    group.add_argument("--certfile", type=Path, help="PEM certificate chain to serve HTTPS with")
    group.add_argument("--keyfile", type=Path, help="PEM private key of --certfile")
    group.add_argument(
        "--self-signed",
        action="store_true",
        help="serve HTTPS with a certificate from a local CA made on first use and kept",
    )
    group.add_argument(
        "--state-dir",
        type=Path,
        help=f"where --self-signed keeps its CA and certificate (default {default_state_dir()})",
    )


def from_arguments(args: argparse.Namespace) -> TlsFiles | None:
    """The files to serve HTTPS with, or None for plain HTTP; ``ValueError`` names a bad mix."""
    certfile: Path | None = args.certfile
    keyfile: Path | None = args.keyfile
    if args.self_signed:
        if certfile or keyfile:
            raise ValueError("give either --self-signed or --certfile/--keyfile, not both")
        files = self_signed(args.state_dir)
        assert files.ca_file is not None
        log.info("serving HTTPS; to trust it: %s", trust_instructions(files.ca_file))
        return files
    if certfile is None and keyfile is None:
        return None
    if certfile is None or keyfile is None:
        raise ValueError("--certfile and --keyfile go together")
    for path in (certfile, keyfile):
        if not path.is_file():
            raise ValueError(f"no such file: {path}")
    return TlsFiles(certfile=certfile, keyfile=keyfile)


LOCAL_HOSTS = frozenset({"localhost", "127.0.0.1", "::1"})
ROSBRIDGE_TLS_FIX = (
    "start rosbridge with its own TLS (roslaunch rosbridge_server rosbridge_websocket.launch "
    "ssl:=true certfile:=CERT keyfile:=KEY, or the same arguments to ros2 launch "
    "rosbridge_server rosbridge_websocket_launch.xml) and use wss://"
)


def insecure_rosbridge(url: str, page_scheme: str) -> str | None:
    """Why a page served over ``page_scheme`` must not use the rosbridge at ``url``, or None.

    An HTTPS page may open ``ws://`` only to this machine (browsers treat localhost as
    secure); anywhere else the browser blocks it as mixed content and the rosbridge's traffic
    would cross the network in clear.
    """
    parts = urlsplit(url)
    if parts.scheme not in ("ws", "wss") or not parts.hostname:
        return f"the rosbridge URL must look like wss://host:9090, not {url!r}"
    if page_scheme != "https" or parts.scheme == "wss":
        return None
    host = parts.hostname.lower()
    if host in LOCAL_HOSTS or host.endswith(".localhost"):
        return None
    return (
        f"refusing the rosbridge at {url}: this page is served over HTTPS, so a ws:// rosbridge "
        f"on another machine is blocked as mixed content; {ROSBRIDGE_TLS_FIX}"
    )
