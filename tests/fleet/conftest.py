"""Fixtures of the fleet tests: ``autopilot serve`` processes sharing the test's Redis."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Protocol

import httpx
import pytest

from app.supervise import free_port

REPO = Path(__file__).resolve().parents[2]


class ServeProcess(Protocol):
    """Starts one ``autopilot serve`` process (``env``: more settings); its base URL and process."""

    def __call__(
        self, env: dict[str, str] | None = None
    ) -> tuple[str, subprocess.Popen[bytes]]: ...


def wait_healthy(url: str, process: subprocess.Popen[bytes], log: Path) -> None:
    """Until ``url/healthz`` answers; fails with the process's log if it exits or hangs."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and process.poll() is None:
        try:
            if httpx.get(f"{url}/healthz", timeout=1).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    raise RuntimeError(f"{url} did not become healthy:\n{log.read_text()}")


@pytest.fixture
def serve_process(redis_url: str, tmp_path: Path) -> Iterator[ServeProcess]:
    """Start ``autopilot serve`` instances as their own processes, so that they can be killed."""
    processes: list[subprocess.Popen[bytes]] = []

    def start(env: dict[str, str] | None = None) -> tuple[str, subprocess.Popen[bytes]]:
        port = free_port()
        extra = env or {}
        env = {**os.environ, "AUTOPILOT_REDIS_URL": redis_url}
        env.pop("AUTOPILOT_TOKEN", None)
        env.pop("AUTOPILOT_SECRET", None)
        env["AUTOPILOT_ENVIRONMENT"] = "development"
        env.update(extra)
        log = tmp_path / f"serve-{port}.log"
        with log.open("wb") as out:
            process = subprocess.Popen(
                [sys.executable, "-m", "app.cli", "serve", "--port", str(port)],
                cwd=REPO,
                env=env,
                stdout=out,
                stderr=subprocess.STDOUT,
            )
        processes.append(process)
        url = f"http://127.0.0.1:{port}"
        wait_healthy(url, process, log)
        return url, process

    yield start
    for process in processes:
        if process.poll() is None:
            process.terminate()
            process.wait(timeout=10)
