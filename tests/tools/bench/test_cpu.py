"""CPU accounting of process trees from /proc (the fleet bench's "where the cores went")."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from app.tools.bench.cpu import chromium_type, cores_used, parse_stat, thread_cpu, tree_cpu_s

BUSY = "import time\nend = time.monotonic() + 1.5\nwhile time.monotonic() < end: pass\n"
IDLE = "import time\ntime.sleep(1.5)\n"


def test_a_busy_tree_uses_a_core_and_an_idle_one_none() -> None:
    # The busy process is a grandchild: trees count descendants, not only the root.
    busy = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"import subprocess, sys; subprocess.run([sys.executable, '-c', {BUSY!r}])",
        ]
    )
    idle = subprocess.Popen([sys.executable, "-c", IDLE])
    try:
        time.sleep(0.4)  # both interpreters have started
        groups = {"busy": [busy.pid], "idle": [idle.pid], "rest": [os.getpid()]}
        before, start = tree_cpu_s(groups), time.monotonic()
        time.sleep(0.8)
        cores = cores_used(before, tree_cpu_s(groups), time.monotonic() - start)
    finally:
        busy.wait(10)
        idle.wait(10)
    # A spinning process gets a core to itself on a quiet machine, but only its share of one
    # when the suite's other workers run beside it: well above nothing, and far above the idle
    # tree (which sleeps through the window whatever the load).
    assert cores["busy"] > 0.1, cores
    assert cores["idle"] < 0.1 and cores["busy"] > 5 * cores["idle"], cores
    # The children were counted in their own groups, not again in the parent's.
    assert cores["rest"] < 0.5, cores


def test_a_process_that_is_gone_counts_as_nothing() -> None:
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait(10)
    assert tree_cpu_s({"gone": [done.pid]}) == {"gone": 0.0}


def test_threads_are_named_and_timed_with_their_process_kind() -> None:
    # A spinning thread named by the kernel (comm): it shows up under this process, busy.
    import threading

    stop = threading.Event()

    def spin() -> None:
        while not stop.is_set():
            pass

    worker = threading.Thread(target=spin, name="spinner")
    worker.start()
    try:
        time.sleep(0.3)
        found = thread_cpu(os.getpid())
    finally:
        stop.set()
        worker.join()
    mine = [t for t in found if t.pid == os.getpid()]
    assert {t.process for t in mine} == {"browser"}  # no --type: a main process
    assert any(t.tid == os.getpid() for t in mine)
    spinner = [t for t in mine if t.tid == worker.native_id]
    assert spinner and spinner[0].cpu_s > 0.05, spinner


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
