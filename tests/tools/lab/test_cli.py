"""``autopilot lab`` builds the lab, says where the sites are, and leaves nothing on Ctrl-C."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time

from app.tools.lab import netns
from tests.helpers.processes import alive, descendants


def test_lab_command_builds_describes_and_tears_down_on_ctrl_c() -> None:
    process = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "lab", "--condition", "turn_only"],
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stderr is not None
    lines: list[str] = []
    deadline = time.monotonic() + 30
    while not any("lab is up" in line for line in lines):
        assert time.monotonic() < deadline and process.poll() is None, lines
        lines.append(process.stderr.readline())
    text = "".join(lines)
    namespaces = set(re.findall(r"namespace (\S+)", text))
    assert len(namespaces) == 3 and namespaces <= set(netns.list_names())
    assert "relay" in text and "ip netns exec" in text
    children = descendants(process.pid)
    assert children, "coturn should be running under the lab"

    process.send_signal(signal.SIGINT)
    assert process.wait(timeout=30) == 0
    process.stderr.close()
    assert namespaces.isdisjoint(netns.list_names())
    assert not any(alive(pid) for pid in children)
