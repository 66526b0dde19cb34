"""CPU accounting of process trees from /proc (the fleet bench's "where the cores went")."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from app.tools.bench.cpu import cores_used, tree_cpu_s

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
