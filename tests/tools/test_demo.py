"""``autopilot demo`` as a user runs it: it starts, prints the client URL, piloting works from
the client page, and SIGTERM ends every process it started.

Run inside the private network namespace: ``scripts/in-netns python -m pytest tests/test_demo.py``.
"""

from __future__ import annotations

import json
import math
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from queue import Empty, Queue

import pytest
from playwright.sync_api import sync_playwright

from app.tools.browser import chromium_args, chromium_path
from tests.helpers.processes import descendants, wait_all_gone

pytestmark = [pytest.mark.browser, pytest.mark.e2e, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]


def turtle_theta(base: str) -> float:
    with urllib.request.urlopen(f"{base}/turtlesim/state", timeout=10) as response:
        state = json.load(response)
    turtle = next(t for t in state["turtles"] if t["name"] == "turtle1")
    return float(turtle["theta"])


@pytest.fixture
def demo() -> Iterator[tuple[subprocess.Popen[str], Queue[str]]]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "demo", "--port", str(port)],
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
        if process.poll() is None:
            for pid in descendants(process.pid):
                with_suppressed_kill(pid)
            process.kill()
        process.wait(timeout=30)
        assert process.stdout is not None
        process.stdout.close()


def with_suppressed_kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def wait_for_line(lines: Queue[str], pattern: str, timeout: float) -> re.Match[str]:
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


def test_demo_runs_pilots_and_ends_every_child_on_sigterm(
    demo: tuple[subprocess.Popen[str], Queue[str]],
) -> None:
    process, lines = demo
    url = wait_for_line(lines, r"(http://\S+/client\?room=default)", 60).group(1)
    base = url.split("/client")[0]
    with urllib.request.urlopen(url, timeout=10) as response:
        assert response.status == 200
        assert "Start Piloting" in response.read().decode()

    with sync_playwright() as pw:
        browser = pw.chromium.launch(
            executable_path=chromium_path(), args=chromium_args(), headless=True
        )
        try:
            page = browser.new_page()
            page.goto(url)
            # What a person does: Connect, Join Room, then Start Piloting once it is enabled.
            page.get_by_role("button", name="Connect").click()
            join = page.get_by_role("button", name="Join Room")
            page.wait_for_function(
                "() => !document.querySelector('[data-action=join]').disabled", timeout=30_000
            )
            join.click()
            page.wait_for_function(
                "() => !document.querySelector('[data-action=start]').disabled", timeout=120_000
            )
            before = turtle_theta(base)
            page.get_by_role("button", name="Start Piloting").click()
            clicked = time.monotonic()
            # Goals reach the agent, whose Twists turn the server's turtle through /rosbridge.
            while abs(math.remainder(turtle_theta(base) - before, math.tau)) < 0.3:
                assert time.monotonic() - clicked < 30, "the turtle did not turn after Start"
                time.sleep(0.1)
            (REPO / "artifacts").mkdir(exist_ok=True)
            page.screenshot(path=str(REPO / "artifacts" / "demo-client.png"))
        finally:
            browser.close()

    children = descendants(process.pid)
    # The relay's Chromium and the agent are among them.
    assert len(children) >= 3, children
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=60) == 0
    assert wait_all_gone(children) == []
