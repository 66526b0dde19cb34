"""CPU time of process trees, from ``/proc``: where a benchmark's cores went.

Linux only; without ``/proc`` every group reads 0 s. A process that ends inside a window takes
its CPU time with it (it is only counted while alive), so windows should be spans where the
measured processes all run.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

PROC = Path("/proc")
_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def parse_stat(stat: str) -> tuple[str, int, float]:
    """(command name, parent pid, CPU seconds) from a ``/proc/<pid>[/task/<tid>]/stat`` line."""
    # The command name (field 2) may hold spaces and parentheses: split after the last ')'.
    head, tail = stat.rsplit(")", 1)
    fields = tail.split()
    parent, user, system = int(fields[1]), int(fields[11]), int(fields[12])
    return head.split("(", 1)[1], parent, (user + system) / _TICKS


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
        _, parent, seconds = parse_stat(stat)
        found[int(entry.name)] = (parent, seconds)
    return found


def _descendants(root: int) -> list[int]:
    """``root`` and every process below it."""
    children: dict[int, list[int]] = {}
    for pid, (parent, _) in _processes().items():
        children.setdefault(parent, []).append(pid)
    found, stack = [], [root]
    while stack:
        pid = stack.pop()
        found.append(pid)
        stack.extend(children.get(pid, ()))
    return found


def chromium_type(argv: Iterable[str]) -> str:
    """A Chromium process's kind from its command line: ``renderer``, ``gpu-process``,
    ``utility:<sub-type>``, ``zygote``..., or ``browser`` (the main process has no ``--type``).

    Chromium rewrites its processes' titles, so the arguments may arrive joined by spaces.
    """
    words = [word for arg in argv for word in arg.split(" ")]
    kind = next((w.split("=", 1)[1] for w in words if w.startswith("--type=")), "browser")
    sub = next((w.split("=", 1)[1] for w in words if w.startswith("--utility-sub-type=")), None)
    return f"{kind}:{sub}" if sub else kind


@dataclass(frozen=True)
class ThreadCpu:
    """One thread's CPU time so far, with its process's kind and the thread's name."""

    process: str
    pid: int
    tid: int
    name: str
    cpu_s: float


def thread_cpu(root: int) -> list[ThreadCpu]:
    """Every thread of ``root``'s process tree with its CPU seconds so far (threads that end
    meanwhile are skipped)."""
    found = []
    for pid in _descendants(root):
        try:
            argv = (PROC / str(pid) / "cmdline").read_bytes().decode(errors="replace").split("\0")
            tasks = list((PROC / str(pid) / "task").iterdir())
        except OSError:
            continue
        kind = chromium_type(argv)
        for task in tasks:
            try:
                name, _, seconds = parse_stat((task / "stat").read_text())
            except OSError:
                continue
            found.append(ThreadCpu(kind, pid, int(task.name), name, seconds))
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
