"""Real flight recordings for tests: the recorder's own files, from a synthetic camera and the
goals a relay would send for its frames."""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from pathlib import Path

from app.protocol import events as ev
from vehicle_agent.events import EventLog, Listener
from vehicle_agent.recorder import FlightRecorder, RecordSettings
from vehicle_agent.video import SyntheticVideo

# Small chunks, so that a short recording has several (a cut or a flipped bit lands in one).
SMALL_CHUNK_BYTES = 16 * 1024


async def record(
    settings: RecordSettings,
    seconds: float,
    recorder: FlightRecorder | None = None,
    listeners: Sequence[Listener] = (),
) -> FlightRecorder:
    """Record a synthetic camera for ``seconds`` while goals arrive, 60 ms late, for every
    other frame, with a pose and a Twist beside each; ``recorder``: an open one to record to;
    ``listeners``: more listeners of the events."""
    recorder = recorder or FlightRecorder(settings)
    events = EventLog()
    events.listeners += [recorder.on_event, *listeners]
    loop = asyncio.get_running_loop()

    def answer(sent: ev.FrameSent) -> None:
        if sent.frame % 2:
            return
        t = sent.t + 0.06
        goal = ev.GoalApplied(
            seq=sent.frame, op="face", frame=sent.frame, x=sent.face_x, y=sent.face_y, w=320,
            h=240, t=t,
        )  # fmt: skip
        twist = ev.TwistSent(seq=sent.frame, frame=sent.frame, linear=0.5, angular=0.1, t=t)
        pose = ev.PoseReport(x=5.5, y=5.5, theta=1.0, sent=True, t=t)
        for event in (goal, twist, pose):
            loop.call_later(0.06, events.emit, event)

    return await record_for(recorder, SyntheticVideo(320, 240, fps=20, on_frame=answer), seconds)


async def record_for(
    recorder: FlightRecorder, video: SyntheticVideo, seconds: float
) -> FlightRecorder:
    """``recorder`` recording ``video`` for ``seconds``, then closed."""
    camera = asyncio.create_task(recorder.record_video(video))
    await asyncio.sleep(seconds)
    camera.cancel()
    video.stop()
    await recorder.close()
    return recorder


def small_recording(folder: Path, seconds: float = 1.2) -> Path:
    """One finished file of about a second: images, goals, Twists and poses, in small chunks."""
    settings = RecordSettings(folder, room="test", fps=10, chunk_bytes=SMALL_CHUNK_BYTES)
    recorder = asyncio.run(record(settings, seconds))
    [path] = recorder.files
    return path
