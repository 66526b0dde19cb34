"""CPU time of process trees, from ``/proc``: where a benchmark's cores went.

Linux only; without ``/proc`` every group reads 0 s. A process that ends inside a window takes
its CPU time with it (it is only counted while alive), so windows should be spans where the
measured processes all run.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from pathlib import Path

PROC = Path("/proc")
_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _processes() -> dict[int, tuple[int, float]]:
    """pid -> (parent pid, CPU seconds used so far) of every readable process."""
    found = {}
    for entry in PROC.iterdir() if PROC.is_dir() else ():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue  # ended meanwhile
        # The command name (field 2) may hold spaces and parentheses: split after the last ')'.
        fields = stat.rsplit(")", 1)[1].split()
        parent, user, system = int(fields[1]), int(fields[11]), int(fields[12])
        found[int(entry.name)] = (parent, (user + system) / _TICKS)
    return found


def tree_cpu_s(groups: Mapping[str, Iterable[int]]) -> dict[str, float]:
    """CPU seconds used so far by each group of process trees (roots and all descendants).

    A process in several groups' trees counts in the first group only, so groups may name a
    parent after its children's own groups (``{"agents": [...], "everything": [os.getpid()]}``).
    """
    processes = _processes()
    children: dict[int, list[int]] = {}
    for pid, (parent, _) in processes.items():
        children.setdefault(parent, []).append(pid)
    counted: set[int] = set()
    totals = {}
    for name, roots in groups.items():
        total = 0.0
        stack = [pid for pid in roots if pid in processes]
        while stack:
            pid = stack.pop()
            if pid in counted:
                continue
            counted.add(pid)
            total += processes[pid][1]
            stack.extend(children.get(pid, ()))
        totals[name] = total
    return totals


def cores_used(
    before: Mapping[str, float], after: Mapping[str, float], seconds: float
) -> dict[str, float]:
    """Each group's average number of busy cores between two :func:`tree_cpu_s` readings."""
    return {
        name: round(max(0.0, after[name] - before.get(name, 0.0)) / seconds, 2) for name in after
    }
