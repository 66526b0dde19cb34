"""Named network namespaces (``ip netns``): create, run in, open sockets in, delete.

Works on the host and inside ``scripts/in-netns`` (an ``unshare -n`` namespace): ``ip netns``
keeps its names under /var/run/netns, which lives in the mount namespace, not the network one,
so namespaces made from inside the private namespace are independent of it. Names carry the
creating process's pid (``apl-<pid>-<tag>-<site>``), so parallel runs never clash and a run that
died leaves names :func:`remove_stale` can recognise.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import re
import signal
import socket
import subprocess
import threading
from collections.abc import Iterator, Sequence

log = logging.getLogger(__name__)

PREFIX = "apl"
NETNS_DIR = "/var/run/netns"
_CLONE_NEWNET = 0x40000000
_NAME = re.compile(rf"^{PREFIX}-(\d+)-[0-9a-f]+-[a-z0-9]+$")
_setns_lock = threading.Lock()


class LabError(RuntimeError):
    """A lab command failed; the message carries the command and what it printed."""


def ip(*args: str, namespace: str | None = None, stdin: str | None = None) -> str:
    """Run ``ip`` (optionally ``ip -n NAMESPACE``) and return its output; raise on failure."""
    argv = ["ip", *(["-n", namespace] if namespace else []), *args]
    return run_checked(argv, stdin=stdin)


def run_checked(argv: Sequence[str], stdin: str | None = None) -> str:
    """Run a command, return stdout; a failure raises :class:`LabError` naming the command."""
    done = subprocess.run(list(argv), input=stdin, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise LabError(f"{' '.join(argv)} failed ({done.returncode}): {done.stderr.strip()}")
    return done.stdout


def exec_argv(namespace: str, argv: Sequence[str]) -> list[str]:
    """The argv that runs ``argv`` inside ``namespace``."""
    return ["ip", "netns", "exec", namespace, *argv]


def nft(namespace: str, ruleset: str) -> None:
    """Load an nftables script inside ``namespace``."""
    run_checked(exec_argv(namespace, ["nft", "-f", "-"]), stdin=ruleset)


def list_names() -> list[str]:
    """Names of every namespace ``ip netns`` knows."""
    return [line.split()[0] for line in ip("netns", "list").splitlines() if line.strip()]


def delete(namespace: str) -> None:
    """Stop whatever still runs inside ``namespace`` (started by the lab), then delete it."""
    pids = subprocess.run(
        ["ip", "netns", "pids", namespace], capture_output=True, text=True, check=False
    ).stdout.split()
    for pid in pids:
        with contextlib.suppress(ProcessLookupError):
            os.kill(int(pid), signal.SIGKILL)
    done = subprocess.run(
        ["ip", "netns", "delete", namespace], capture_output=True, text=True, check=False
    )
    if done.returncode != 0:
        log.warning("could not delete namespace %s: %s", namespace, done.stderr.strip())


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale() -> list[str]:
    """Delete lab namespaces whose creating process has gone; return their names."""
    stale = [
        name
        for name in list_names()
        if (match := _NAME.match(name)) and not _alive(int(match.group(1)))
    ]
    for name in stale:
        log.info("removing stale lab namespace %s", name)
        delete(name)
    return stale


@contextlib.contextmanager
def entered(namespace: str) -> Iterator[None]:
    """Move the calling thread into ``namespace`` for the block, then back.

    ``setns`` moves only the calling thread, and a socket stays in the namespace it was created
    in, so a socket opened inside this block talks from that site for its whole life. A lock keeps
    two threads from interleaving their switches.
    """
    libc = ctypes.CDLL(None, use_errno=True)
    with (
        _setns_lock,
        open("/proc/thread-self/ns/net", "rb") as home,
        open(os.path.join(NETNS_DIR, namespace), "rb") as target,
    ):
        if libc.setns(target.fileno(), _CLONE_NEWNET) != 0:
            raise LabError(f"setns into {namespace}: {os.strerror(ctypes.get_errno())}")
        try:
            yield
        finally:
            if libc.setns(home.fileno(), _CLONE_NEWNET) != 0:
                raise LabError(f"setns back home: {os.strerror(ctypes.get_errno())}")


def open_socket(namespace: str, kind: socket.SocketKind = socket.SOCK_DGRAM) -> socket.socket:
    """An IPv4 socket that lives in ``namespace``."""
    with entered(namespace):
        return socket.socket(socket.AF_INET, kind)
