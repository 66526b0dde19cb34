"""The one WebSocket adapter's outbox: bounded in messages and bytes, never NaN."""

from __future__ import annotations

import math

from app.server.websocket import Outbox, Shut


async def test_an_outbox_over_its_byte_bound_closes_the_slow_reader() -> None:
    outbox = Outbox(max_messages=100, max_bytes=1000)
    for n in range(5):
        outbox.send({"type": "peers", "pad": "x" * 300, "n": n})
    assert len(outbox) == 0
    shut = await outbox.get()
    assert isinstance(shut, Shut) and shut.code == 1013 and "unread" in shut.reason


async def test_droppable_messages_are_dropped_not_fatal_while_full() -> None:
    outbox = Outbox(max_messages=2, max_bytes=10_000)
    assert outbox.offer({"op": "publish", "n": 1}) and outbox.offer({"op": "publish", "n": 2})
    assert outbox.offer({"op": "publish", "n": 3}) is False
    assert outbox.shut is None
    assert await outbox.get() == '{"op":"publish","n":1}'
    outbox.send({"op": "status"})  # there is room again: a reply fits
    assert len(outbox) == 2


async def test_nan_is_never_queued() -> None:
    outbox = Outbox(max_messages=10, max_bytes=10_000)
    outbox.send({"type": "pose", "x": math.nan})
    assert outbox.offer({"op": "publish", "msg": {"x": math.inf}}) is False
    assert len(outbox) == 0 and outbox.shut is None


async def test_the_close_comes_after_what_was_queued_before_it() -> None:
    outbox = Outbox(max_messages=10, max_bytes=10_000)
    outbox.send({"type": "error", "reason": "bye"})
    outbox.close(1008, "abusive")
    outbox.send({"type": "late"})
    assert await outbox.get() == '{"type":"error","reason":"bye"}'
    assert await outbox.get() == Shut(1008, "abusive")
