"""The delay stage on loopback: every datagram goes through, in order, no sooner than the delay."""

from __future__ import annotations

import asyncio
import time
from typing import cast

from app.tools.lab.delay import DelayStage

ONE_WAY_S = 0.03
JITTER_S = 0.01
COUNT = 40


class _Echo(asyncio.DatagramProtocol):
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.transport.sendto(data, addr)


class _Client(asyncio.DatagramProtocol):
    def __init__(self) -> None:
        self.received: asyncio.Queue[tuple[bytes, float]] = asyncio.Queue()

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.received.put_nowait((data, time.monotonic()))


async def test_echo_through_the_stage_arrives_in_order_after_twice_the_delay() -> None:
    loop = asyncio.get_running_loop()
    echo, _ = await loop.create_datagram_endpoint(_Echo, local_addr=("127.0.0.1", 0))
    stage = DelayStage(echo.get_extra_info("sockname")[:2], ONE_WAY_S, JITTER_S)
    listen = await stage.start(("127.0.0.1", 0))
    client, protocol = await loop.create_datagram_endpoint(_Client, remote_addr=listen)
    try:
        sent = []
        for i in range(COUNT):
            sent.append(time.monotonic())
            client.sendto(i.to_bytes(4, "big"))
            await asyncio.sleep(0.002)
        got = [await asyncio.wait_for(protocol.received.get(), 2) for _ in range(COUNT)]
    finally:
        client.close()
        stage.close()
        echo.close()
    assert [int.from_bytes(data, "big") for data, _ in got] == list(range(COUNT))
    round_trips = [at - sent[i] for i, (_, at) in enumerate(got)]
    assert min(round_trips) >= 2 * (ONE_WAY_S - JITTER_S)


async def test_jitter_larger_than_the_delay_is_refused() -> None:
    try:
        DelayStage(("127.0.0.1", 9), 0.01, 0.02)
    except ValueError as exc:
        assert "jitter" in str(exc)
    else:
        raise AssertionError("a jitter larger than the delay was accepted")
