"""coturn for the lab: a temporary config with the TURN REST shared secret.

coturn listens on the lab's cloud address only, logs to a file in the lab's temporary directory
(never syslog), keeps its pid file and user database there too, and speaks plain UDP/TCP (no TLS,
no DTLS, no CLI).
"""

from __future__ import annotations

from pathlib import Path

REALM = "autopilot.lab"
TURN_PORT = 3478
RELAY_MIN_PORT = 49152
RELAY_MAX_PORT = 65535


def config(workdir: Path, address: str, secret: str, port: int = TURN_PORT) -> str:
    """The text of a turnserver.conf for the lab."""
    return "\n".join(
        [
            f"listening-ip={address}",
            f"relay-ip={address}",
            f"listening-port={port}",
            f"min-port={RELAY_MIN_PORT}",
            f"max-port={RELAY_MAX_PORT}",
            f"realm={REALM}",
            "use-auth-secret",
            f"static-auth-secret={secret}",
            "fingerprint",
            "no-tls",
            "no-dtls",
            "no-cli",
            "no-multicast-peers",
            "no-software-attribute",
            f"log-file={workdir / 'turnserver.log'}",
            "simple-log",
            f"pidfile={workdir / 'turnserver.pid'}",
            f"userdb={workdir / 'turndb'}",
            "",
        ]
    )


def write_config(workdir: Path, address: str, secret: str, port: int = TURN_PORT) -> Path:
    """Write the config into ``workdir`` (readable by its owner only: it holds the secret)."""
    path = workdir / "turnserver.conf"
    path.touch(mode=0o600)
    path.write_text(config(workdir, address, secret, port))
    return path


def argv(config_path: Path) -> list[str]:
    """The command line that runs coturn on ``config_path``."""
    return ["turnserver", "-c", str(config_path), "--no-stdout-log"]
