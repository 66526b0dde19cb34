"""``autopilot demo`` as a subprocess for the tests that run it whole: its output read line by
line, and every process it started killed when the test ends."""

from __future__ import annotations

import contextlib
import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from queue import Empty, Queue

from tests.helpers.processes import kill_tree

REPO = Path(__file__).resolve().parents[2]


@contextlib.contextmanager
def running_demo(args: list[str]) -> Iterator[tuple[subprocess.Popen[str], Queue[str]]]:
    """``autopilot demo ARGS`` on a free loopback port: the process and a queue of its output
    lines (stdout and stderr together). On leaving, the demo and every process below it are
    killed."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "demo", "--port", str(port), *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    lines: Queue[str] = Queue()

    def pump() -> None:
        assert process.stdout is not None
        for line in process.stdout:
            lines.put(line)

    threading.Thread(target=pump, daemon=True).start()
    try:
        yield process, lines
    finally:
        kill_tree(process)
        assert process.stdout is not None
        process.stdout.close()


def wait_for_line(lines: Queue[str], pattern: str, timeout: float) -> re.Match[str]:
    """The first line matching ``pattern`` within ``timeout`` seconds (the last lines seen are
    in the error otherwise)."""
    deadline = time.monotonic() + timeout
    seen: list[str] = []
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
        except Empty:
            break
        seen.append(line)
        found = re.search(pattern, line)
        if found:
            return found
    raise AssertionError(f"no line matching {pattern!r} in {timeout:g} s:\n{''.join(seen[-40:])}")
