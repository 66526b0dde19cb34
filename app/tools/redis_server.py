"""A real, throwaway ``redis-server`` (Debian's) on a free loopback port, for tests and benches.

Redis cannot bind port 0, so a free port is picked and the start is retried on another one if
something took it in the meantime.
"""

from __future__ import annotations

import contextlib
import shutil
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import redis

from app.supervise import free_port

ATTEMPTS = 5


@contextlib.contextmanager
def redis_server(workdir: Path) -> Iterator[str]:
    """Run ``redis-server`` (no persistence) until the block ends; yields its ``redis://`` URL."""
    binary = shutil.which("redis-server")
    if binary is None:
        raise RuntimeError("redis-server not found: run scripts/setup (it installs redis-server)")
    for _ in range(ATTEMPTS):
        port = free_port()
        process = subprocess.Popen(
            [
                binary,
                "--port",
                str(port),
                "--bind",
                "127.0.0.1",
                "--save",
                "",
                "--appendonly",
                "no",
                "--dir",
                str(workdir),
                "--loglevel",
                "warning",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        url = f"redis://127.0.0.1:{port}/0"
        if _wait_ready(process, url):
            try:
                yield url
            finally:
                process.terminate()
                process.wait(timeout=10)
            return
        process.kill()
        process.wait(timeout=10)
    raise RuntimeError(f"redis-server did not start on a free port in {ATTEMPTS} attempts")


def _wait_ready(process: subprocess.Popen[bytes], url: str) -> bool:
    client = redis.Redis.from_url(url)
    try:
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if process.poll() is not None:
                return False  # exited: most likely the port was taken
            with contextlib.suppress(redis.ConnectionError):
                if client.ping():
                    return True
            time.sleep(0.05)
        return False
    finally:
        client.close()
