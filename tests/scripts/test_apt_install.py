"""``scripts/apt-install`` (what ``scripts/setup`` installs Debian packages with) waits, for a
bounded time and saying so, while another process holds apt's or dpkg's lock (issue 37.12).

The locks here are files of the test's own, held the way apt and dpkg hold theirs (fcntl); a
stand-in ``apt-get`` records what it was asked: nothing is installed."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "scripts" / "apt-install"
HOLD = """
import fcntl, sys, time
lock = open(sys.argv[1], "w")
fcntl.lockf(lock, fcntl.LOCK_EX)
print("held", flush=True)
time.sleep(float(sys.argv[2]))
"""


@pytest.fixture
def fake_apt(tmp_path: Path) -> Path:
    """A directory whose ``apt-get`` records its arguments, one call a line, in ``calls``."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    apt_get = bin_dir / "apt-get"
    apt_get.write_text(f'#!/bin/sh\necho "$*" >> {tmp_path / "calls"}\n')
    apt_get.chmod(0o755)
    return bin_dir


@pytest.fixture
def lock(tmp_path: Path) -> Path:
    path = tmp_path / "lock-frontend"
    path.touch()
    return path


def _hold(lock: Path, seconds: float) -> subprocess.Popen[str]:
    """Another process holding ``lock`` for ``seconds``, as a running dpkg would."""
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(lock), str(seconds)], stdout=subprocess.PIPE, text=True
    )
    assert holder.stdout is not None and holder.stdout.readline() == "held\n"
    return holder


@pytest.fixture
def holders() -> Iterator[list[subprocess.Popen[str]]]:
    started: list[subprocess.Popen[str]] = []
    yield started
    for holder in started:
        holder.kill()
        holder.wait()
        if holder.stdout is not None:
            holder.stdout.close()


def _install(fake_apt: Path, lock: Path, timeout_s: float) -> subprocess.CompletedProcess[str]:
    env = {
        **os.environ,
        "PATH": f"{fake_apt}:{os.environ['PATH']}",
        "AUTOPILOT_APT_LOCKS": str(lock),
        "AUTOPILOT_APT_LOCK_TIMEOUT_S": str(timeout_s),
    }
    return subprocess.run(
        [str(SCRIPT), "coturn", "redis-server"], env=env, capture_output=True, text=True, timeout=60
    )


def _calls(fake_apt: Path) -> list[str]:
    calls = fake_apt.parent / "calls"
    return calls.read_text().splitlines() if calls.exists() else []


def test_a_held_lock_is_waited_for_then_given_up_with_who_holds_it(
    fake_apt: Path, lock: Path, holders: list[subprocess.Popen[str]]
) -> None:
    holder = _hold(lock, 60)
    holders.append(holder)
    started = time.monotonic()
    result = _install(fake_apt, lock, timeout_s=1)
    assert result.returncode == 1
    assert time.monotonic() - started < 30
    assert f"{lock} is held by PID {holder.pid} (python3" in result.stderr
    assert "waiting for it, at most 1 s" in result.stderr
    assert f"{lock} is still held by PID {holder.pid}" in result.stderr
    assert "after 1 s" in result.stderr and "Traceback" not in result.stderr
    assert _calls(fake_apt) == []  # apt-get was never run into the lock


def test_a_lock_given_back_in_time_is_waited_for_and_the_install_goes_on(
    fake_apt: Path, lock: Path, holders: list[subprocess.Popen[str]]
) -> None:
    holders.append(_hold(lock, 1.5))
    result = _install(fake_apt, lock, timeout_s=30)
    assert result.returncode == 0, result.stderr
    assert "waiting for it, at most 30 s" in result.stderr
    assert f"{lock} is free now" in result.stderr
    # apt-get itself is told to wait too, should another take the lock in between.
    assert _calls(fake_apt) == [
        "-o DPkg::Lock::Timeout=30 update -qq",
        "-o DPkg::Lock::Timeout=30 install -y -qq coturn redis-server",
    ]


def test_a_free_lock_costs_no_wait_and_no_words(fake_apt: Path, lock: Path) -> None:
    result = _install(fake_apt, lock, timeout_s=30)
    assert result.returncode == 0 and result.stderr == ""
    assert len(_calls(fake_apt)) == 2
