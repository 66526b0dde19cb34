"""A userspace UDP delay stage: what netem would do, for a kernel without netem.

It listens on one address and keeps one upstream socket per downstream sender (so the upstream
server sees each sender as its own 5-tuple), and delivers every datagram ``delay +- jitter``
later in each direction. Delivery within a flow and direction stays in order, as a queue on a
real link would keep it: a datagram is never delivered before the one sent ahead of it.

``python -m app.tools.lab.delay --listen H:P --upstream H:P --delay-ms D --jitter-ms J`` writes
``ready`` on stdout once listening and runs until SIGTERM/SIGINT.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import random
import signal
import socket
import sys
from collections import deque
from collections.abc import Callable

from app.arguments import non_negative_number

log = logging.getLogger(__name__)

Address = tuple[str, int]
MAX_FLOWS = 1024
MAX_DATAGRAM = 65535


class _Lane:
    """One direction of one flow: a queue of datagrams, each with the time it is due.

    Due times never decrease along the queue and one timer drains it from the head, so datagrams
    leave in the order they came (the event loop's timer heap alone would not keep equal due
    times in order).
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, send: Callable[[bytes], None]) -> None:
        self._loop = loop
        self._send = send
        self._queue: deque[tuple[float, bytes]] = deque()
        self._last_due = 0.0
        self._timer: asyncio.TimerHandle | None = None

    def push(self, data: bytes, delay_s: float) -> None:
        """Deliver ``data`` after ``delay_s``, but never ahead of an earlier datagram."""
        self._last_due = max(self._last_due, self._loop.time() + delay_s)
        self._queue.append((self._last_due, data))
        if self._timer is None:
            self._timer = self._loop.call_at(self._last_due, self._drain)

    def _drain(self) -> None:
        self._timer = None
        now = self._loop.time()
        while self._queue and self._queue[0][0] <= now:
            self._send(self._queue.popleft()[1])
        if self._queue:
            self._timer = self._loop.call_at(self._queue[0][0], self._drain)

    def cancel(self) -> None:
        """Drop whatever is still queued."""
        if self._timer is not None:
            self._timer.cancel()
        self._queue.clear()


class DelayStage(asyncio.DatagramProtocol):
    """The stage; :meth:`start` binds it, :meth:`close` stops it."""

    def __init__(
        self, upstream: Address, delay_s: float, jitter_s: float, rng: random.Random | None = None
    ) -> None:
        if delay_s < 0 or jitter_s < 0 or jitter_s > delay_s:
            raise ValueError("need 0 <= jitter <= delay")
        self.upstream = upstream
        self.delay_s = delay_s
        self.jitter_s = jitter_s
        self._rng = rng or random.Random()
        self._loop = asyncio.get_running_loop()
        self._transport: asyncio.DatagramTransport | None = None
        self._flows: dict[Address, tuple[socket.socket, _Lane, _Lane]] = {}

    async def start(self, listen: Address) -> Address:
        """Bind to ``listen`` and return the bound address."""
        transport, _ = await self._loop.create_datagram_endpoint(lambda: self, local_addr=listen)
        self._transport = transport
        bound: Address = transport.get_extra_info("sockname")[:2]
        return bound

    def close(self) -> None:
        """Stop listening and drop every flow (datagrams in flight are lost)."""
        if self._transport is not None:
            self._transport.close()
        for sock, up, down in self._flows.values():
            up.cancel()
            down.cancel()
            self._loop.remove_reader(sock.fileno())
            sock.close()
        self._flows.clear()

    def _delay(self) -> float:
        return self.delay_s + self._rng.uniform(-self.jitter_s, self.jitter_s)

    def datagram_received(self, data: bytes, addr: Address) -> None:
        """A datagram from downstream: forward it upstream later."""
        flow = self._flows.get(addr) or self._open_flow(addr)
        if flow is None:
            return
        flow[1].push(data, self._delay())

    def _open_flow(self, addr: Address) -> tuple[socket.socket, _Lane, _Lane] | None:
        if len(self._flows) >= MAX_FLOWS:
            log.warning(
                "delay stage: %d flows already, dropping a datagram from %s", MAX_FLOWS, addr
            )
            return None
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setblocking(False)
        sock.connect(self.upstream)
        up = _Lane(self._loop, lambda data: self._send_up(sock, data))
        down = _Lane(self._loop, lambda data: self._send_down(data, addr))
        flow = (sock, up, down)
        self._flows[addr] = flow
        self._loop.add_reader(sock.fileno(), self._from_upstream, addr)
        return flow

    def _send_up(self, sock: socket.socket, data: bytes) -> None:
        try:
            sock.send(data)
        except OSError as exc:  # e.g. ICMP unreachable reported on a connected UDP socket
            log.debug("delay stage: upstream send failed: %s", exc)

    def _from_upstream(self, addr: Address) -> None:
        sock, _, down = self._flows[addr]
        while True:
            try:
                data = sock.recv(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                log.debug("delay stage: upstream receive failed: %s", exc)
                return
            down.push(data, self._delay())

    def _send_down(self, data: bytes, addr: Address) -> None:
        if self._transport is not None and not self._transport.is_closing():
            self._transport.sendto(data, addr)


def _address(text: str) -> Address:
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit():
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)


async def _serve(args: argparse.Namespace) -> None:
    stage = DelayStage(args.upstream, args.delay_ms / 1000, args.jitter_ms / 1000)
    await stage.start(args.listen)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    sys.stdout.write("ready\n")
    sys.stdout.flush()
    try:
        await stop.wait()
    finally:
        stage.close()


def main(argv: list[str] | None = None) -> int:
    """Run the stage as a process (the lab starts it inside a site)."""
    parser = argparse.ArgumentParser(prog="python -m app.tools.lab.delay")
    parser.add_argument("--listen", type=_address, required=True)
    parser.add_argument("--upstream", type=_address, required=True)
    parser.add_argument("--delay-ms", type=non_negative_number, required=True, help="one-way delay")
    parser.add_argument(
        "--jitter-ms", type=non_negative_number, default=0.0, help="one-way jitter (+-)"
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO)
    asyncio.run(_serve(args))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
