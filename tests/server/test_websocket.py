"""The one WebSocket adapter's outbox: bounded in messages and bytes, never NaN."""

from __future__ import annotations

import asyncio
import math

from app.server.websocket import Outbox, Shut


async def test_an_outbox_over_its_byte_bound_closes_the_slow_reader() -> None:
    outbox = Outbox(max_messages=100, max_bytes=1000)
    for n in range(5):
        outbox.send({"type": "peers", "pad": "x" * 300, "n": n})
    assert len(outbox) == 0
    shut = await outbox.get()
    assert isinstance(shut, Shut) and shut.code == 1013 and "unread" in shut.reason


async def test_pulled_messages_are_asked_for_only_when_the_writer_is_free_and_woken() -> None:
    pulls: list[int] = []
    ready: list[str | bytes] = ['{"op":"publish","n":1}', b"\xa2bopgpublishan\x02"]

    def pull() -> list[str | bytes]:
        pulls.append(len(ready))
        taken = ready[:]
        ready.clear()
        return taken

    outbox = Outbox(max_messages=10, max_bytes=10_000, pull=pull)
    outbox.send({"op": "status"})  # what was queued goes first; nothing is pulled meanwhile
    assert await outbox.get() == '{"op":"status"}' and pulls == []
    assert await outbox.get() == '{"op":"publish","n":1}'
    assert await outbox.get() == b"\xa2bopgpublishan\x02"  # a binary frame stays one
    waiting = asyncio.create_task(outbox.get())
    await asyncio.sleep(0)
    assert not waiting.done() and pulls == [2, 0]  # nothing more to pull: it waits
    ready.append('{"op":"publish","n":3}')
    outbox.wake()
    assert await waiting == '{"op":"publish","n":3}'


async def test_nan_is_never_queued() -> None:
    outbox = Outbox(max_messages=10, max_bytes=10_000)
    outbox.send({"type": "pose", "x": math.nan})
    outbox.send({"type": "pose", "x": math.inf})
    assert len(outbox) == 0


async def test_the_close_comes_after_what_was_queued_before_it() -> None:
    outbox = Outbox(max_messages=10, max_bytes=10_000)
    outbox.send({"type": "error", "reason": "bye"})
    outbox.close(1008, "abusive")
    outbox.send({"type": "late"})
    assert await outbox.get() == '{"type":"error","reason":"bye"}'
    assert await outbox.get() == Shut(1008, "abusive")
