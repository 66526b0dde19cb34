"""CPU accounting of process trees from /proc (the fleet bench's "where the cores went")."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.tools.bench.cpu import chromium_type, cores_used, parse_stat, thread_cpu, tree_cpu_s

# Waits on events, never on wall time: a loaded machine may give a spinning process a small
# share of a core, so the busy process says when it has spun SPIN_S of its own CPU time, and the
# figures are checked against that, not against the seconds that took.
SPIN_S = 0.3
# Once told to, spins SPIN_S CPU-seconds, says so, then spins on until the file argv[1] exists
# (a process that is gone counts as nothing, so it must still run when the test reads its tree).
BUSY = f"""import os, sys, time
print('ready', flush=True)
sys.stdin.readline()
start = time.process_time()
while time.process_time() - start < {SPIN_S}:
    pass
print('spun', flush=True)
while not os.path.exists(sys.argv[1]):
    pass
"""
IDLE = "import sys\nprint('ready', flush=True)\nsys.stdin.read()\n"


def test_a_busy_tree_uses_a_core_and_an_idle_one_none(tmp_path: Path) -> None:
    # The busy process is a grandchild: trees count descendants, not only the root.
    stop = tmp_path / "stop"
    middle = "import subprocess, sys; subprocess.run([sys.executable, '-c', *sys.argv[1:]])"
    busy = subprocess.Popen(
        [sys.executable, "-c", middle, BUSY, str(stop)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    idle = subprocess.Popen(
        [sys.executable, "-c", IDLE], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert busy.stdin is not None and busy.stdout is not None
    assert idle.stdin is not None and idle.stdout is not None
    try:
        # Both interpreters have started (what they spent starting is before the window).
        assert busy.stdout.readline() == idle.stdout.readline() == "ready\n"
        groups = {"busy": [busy.pid], "idle": [idle.pid], "rest": [os.getpid()]}
        before, start = tree_cpu_s(groups), time.monotonic()
        busy.stdin.write("go\n")
        busy.stdin.close()
        # This process waits on a pipe meanwhile: it spends next to nothing itself.
        assert busy.stdout.readline() == "spun\n"
        after, seconds = tree_cpu_s(groups), time.monotonic() - start
    finally:
        stop.touch()
        idle.stdin.close()
        for process in (busy, idle):
            process.wait(60)
            assert process.stdout is not None
            process.stdout.close()
    spent = {name: after[name] - before[name] for name in groups}
    # The grandchild's CPU time counted in the busy tree (less a clock tick); nothing of a
    # process asleep on a pipe.
    assert spent["busy"] >= SPIN_S - 0.02 and spent["idle"] < 0.05, spent
    # The children were counted in their own groups, not again in the parent's.
    assert spent["rest"] < SPIN_S / 2, spent
    # Cores: CPU seconds over the window's seconds, per group.
    cores = cores_used(before, after, seconds)
    assert cores == {name: round(spent[name] / seconds, 2) for name in groups}, (cores, spent)


def test_a_process_that_is_gone_counts_as_nothing() -> None:
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait(10)
    assert tree_cpu_s({"gone": [done.pid]}) == {"gone": 0.0}


def test_threads_are_named_and_timed_with_their_process_kind() -> None:
    # A spinning thread named by the kernel (comm): it shows up under this process, busy. It
    # says when it has spun SPIN_S of its own CPU time, and spins on until read.
    import threading

    spun, stop = threading.Event(), threading.Event()

    def spin() -> None:
        start = time.thread_time()
        while not stop.is_set():
            if time.thread_time() - start >= SPIN_S:
                spun.set()

    worker = threading.Thread(target=spin, name="spinner")
    worker.start()
    try:
        assert spun.wait(60)
        found = thread_cpu(os.getpid())
    finally:
        stop.set()
        worker.join()
    mine = [t for t in found if t.pid == os.getpid()]
    assert {t.process for t in mine} == {"browser"}  # no --type: a main process
    assert any(t.tid == os.getpid() for t in mine)
    spinner = [t for t in mine if t.tid == worker.native_id]
    assert spinner and spinner[0].cpu_s >= SPIN_S - 0.02, spinner


def test_chromium_process_kinds_from_their_command_lines() -> None:
    assert chromium_type(["/usr/lib/chromium/chromium", "--headless=new"]) == "browser"
    # Chromium rewrites its titles: the arguments may come joined by spaces.
    assert chromium_type(["/usr/lib/chromium/chromium --type=renderer --lang=en"]) == "renderer"
    utility = "chromium --type=utility --utility-sub-type=network.mojom.NetworkService --x"
    assert chromium_type([utility]) == "utility:network.mojom.NetworkService"


def test_a_stat_line_with_parentheses_in_the_name_parses() -> None:
    stat = "42 (Web (Content)) S 7 42 42 0 -1 4194560 10 0 0 0 250 50 0 0 20 0 1 0"
    name, parent, seconds = parse_stat(stat)
    assert (name, parent) == ("Web (Content)", 7)
    assert seconds == pytest.approx(300 / os.sysconf("SC_CLK_TCK"))
