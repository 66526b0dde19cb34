"""The flight recorder on a disk that refuses: a folder it cannot write is said at start, in one
line; a full disk (a real one: a small tmpfs in a mount namespace of the test's own) costs one
line, the vehicle drives on, the file so far reads back, and recording resumes in a new file
when space returns."""

from __future__ import annotations

import asyncio
import json
import logging
import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path
from typing import Any

import pytest

from app import recording
from app.protocol import events as ev
from app.recording import CutOff
from tests.helpers.recordings import SMALL_CHUNK_BYTES, record
from tests.test_cli_errors import assert_one_line_error
from vehicle_agent.recorder import FlightRecorder, RecorderError, RecordSettings

REPO = Path(__file__).resolve().parents[2]


def _can_mount() -> bool:
    """Whether this process may mount a filesystem in a mount namespace of its own."""
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        return False
    return subprocess.run(["unshare", "-m", "true"], check=False).returncode == 0


needs_mount = pytest.mark.skipif(not _can_mount(), reason="needs root and unshare -m")


def _in_namespace(
    mount: str, folder: Path, *command: str, timeout: float = 60
) -> subprocess.CompletedProcess[str]:
    """``command`` in a mount namespace of its own where ``folder`` is a tmpfs mounted with
    ``mount`` options (the test's machine never sees it)."""
    script = f'mount -t tmpfs -o {mount} none "{folder}" && exec "$@"'
    return subprocess.run(
        ["unshare", "-m", "sh", "-c", script, "sh", *command],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def test_a_folder_that_cannot_be_made_is_said_when_the_recorder_starts(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    with pytest.raises(RecorderError, match=f"cannot record into {blocker}/rec: "):
        FlightRecorder(RecordSettings(blocker / "rec"))


@needs_mount
def test_a_read_only_folder_stops_the_vehicle_at_start_in_one_line(tmp_path: Path) -> None:
    # A folder that is there, read-only as the root user sees it too: a read-only mount, not a
    # chmod. Said before the agent tries its server (nothing listens on port 9).
    agent = [sys.executable, "-m", "vehicle_agent", "--server", "ws://127.0.0.1:9/ws"]
    done = _in_namespace("ro,size=64k", tmp_path, *agent, "--record", str(tmp_path), timeout=30)
    assert_one_line_error(done, f"cannot record into {tmp_path}: Read-only file system")


class _Kept(logging.Handler):
    """Keeps each record's level and message."""

    def __init__(self) -> None:
        super().__init__()
        self.records: list[tuple[str, str]] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append((record.levelname, record.getMessage()))


def full_disk_scenario(folder: str) -> None:
    """Run in the namespace (``folder`` a small tmpfs): fill the disk but for a little, record
    a synthetic camera and goals, free the disk a moment after the recorder first fails, record
    on, and print what came of it as JSON."""
    root = Path(folder)
    space = os.statvfs(root)
    (root / "filler").write_bytes(bytes(space.f_bavail * space.f_frsize - 24 * 1024))
    handler = _Kept()
    logged = handler.records
    logging.getLogger("vehicle_agent").addHandler(handler)
    logging.getLogger("vehicle_agent").setLevel(logging.INFO)
    thread_faults: list[str] = []
    threading.excepthook = lambda hook: thread_faults.append(repr(hook.exc_value))
    settings = RecordSettings(root / "rec", room="disk", fps=10, chunk_bytes=SMALL_CHUNK_BYTES)

    async def run() -> FlightRecorder:
        recorder = FlightRecorder(settings)
        recording_task = asyncio.create_task(record(settings, 4.0, recorder))
        while not any(level == "WARNING" for level, _ in logged) and not recording_task.done():
            await asyncio.sleep(0.05)
        (root / "filler").unlink()  # space returns
        return await recording_task

    recorder = asyncio.run(run())
    files: list[dict[str, Any]] = []
    for path in recorder.files:
        cuts: list[CutOff] = []
        topics = [topic for topic, _, _ in recording.messages([path], cuts.append)]
        images = topics.count(recording.IMAGE_TOPIC)
        files.append({"messages": len(topics), "images": images, "cut": [str(c) for c in cuts]})
    totals = recorder.totals()
    result = {"files": files, "logged": logged, "thread_faults": thread_faults}
    result["totals"] = {"frames": totals.frames, "dropped": totals.dropped}
    sys.stdout.write(json.dumps(result) + "\n")


@needs_mount
def test_a_full_disk_costs_one_line_and_recording_resumes_when_space_returns(
    tmp_path: Path,
) -> None:
    code = f"from {__name__} import full_disk_scenario; full_disk_scenario({str(tmp_path)!r})"
    done = _in_namespace("size=512k", tmp_path, sys.executable, "-c", code)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "Exception" not in done.stderr, done.stderr
    result: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
    assert result["thread_faults"] == [], result
    # One line when the disk refused, one when it took a new file; nothing else to say.
    said = [(level, text) for level, text in result["logged"] if level != "INFO"]
    assert len(said) == 1 and "No space left on device" in said[0][1], result["logged"]
    resumed = [text for _, text in result["logged"] if "writing again" in text]
    assert len(resumed) == 1, result["logged"]
    # The vehicle drove on: the camera ran the whole time (20 fps for 4 s), goals went on.
    assert result["totals"]["frames"] >= 40 and result["totals"]["dropped"] > 0, result
    first, second = result["files"]
    # The file the disk cut off reads up to its cut; the new one is whole, with images.
    assert first["messages"] > 0 and len(first["cut"]) == 1, first
    assert second["images"] > 0 and second["cut"] == [], second


def full_at_close_scenario(folder: str) -> None:
    """Run in the namespace: queue events, fill the disk, close; print what was logged and
    what the file reads back as JSON."""
    root = Path(folder)
    handler = _Kept()
    logging.getLogger("vehicle_agent").addHandler(handler)
    logging.getLogger("vehicle_agent").setLevel(logging.INFO)
    recorder = FlightRecorder(RecordSettings(root / "rec", room="disk"))
    for i in range(400):
        # Operators' names that do not compress: the chunk is more than the disk has left.
        recorder.on_event(ev.ModeChanged(mode="manual", operator=os.urandom(16).hex(), t=i))
    space = os.statvfs(root)
    (root / "filler").write_bytes(bytes(space.f_bavail * space.f_frsize))
    asyncio.run(recorder.close())
    cuts: list[CutOff] = []
    read = len(list(recording.messages(recorder.files, cuts.append)))
    result = {"logged": handler.records, "read": read, "cuts": [str(c) for c in cuts]}
    sys.stdout.write(json.dumps(result) + "\n")


@needs_mount
def test_a_disk_full_when_the_recorder_closes_costs_one_line(tmp_path: Path) -> None:
    code = (
        f"from {__name__} import full_at_close_scenario; full_at_close_scenario({str(tmp_path)!r})"
    )
    done = _in_namespace("size=256k", tmp_path, sys.executable, "-c", code)
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and "Exception" not in done.stderr, done.stderr
    result: dict[str, Any] = json.loads(done.stdout.splitlines()[-1])
    said = [(level, text) for level, text in result["logged"] if level != "INFO"]
    assert len(said) == 1 and "cannot finish" in said[0][1], result
    assert "No space left on device" in said[0][1], result
    # What never reached the disk is lost; the file is what it took, cut off, and reads.
    assert result["read"] == 0 and len(result["cuts"]) == 1, result
