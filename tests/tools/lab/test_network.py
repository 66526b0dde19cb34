"""The lab's network really does what its conditions say: NAT, loss, delay, outage, teardown.

Run inside the private namespace: ``scripts/in-netns python3 -m pytest tests/tools/lab -q``.
"""

from __future__ import annotations

import contextlib
import math
import socket
import subprocess
import time
from collections.abc import Iterator

import pytest
from aioice import stun

from app.tools.lab import Lab, netns
from app.tools.lab.coturn import TURN_PORT
from app.tools.lab.lab import CLOUD, OPERATOR_NAT, ROBOT_NAT

PORT = 40000


def _drain(sock: socket.socket, wait_s: float) -> list[tuple[bytes, tuple[str, int]]]:
    """Everything that arrives on ``sock`` until it has been quiet for ``wait_s``."""
    sock.settimeout(wait_s)
    got = []
    with contextlib.suppress(TimeoutError):
        while True:
            got.append(sock.recvfrom(2048))
    return got


@pytest.mark.parametrize(("site", "nat"), [("robot", ROBOT_NAT), ("operator", OPERATOR_NAT)])
def test_udp_from_behind_a_nat_shows_the_nat_address_and_the_reply_comes_back(
    lab: Lab, site: str, nat: str
) -> None:
    with lab.socket("cloud") as server, lab.socket(site) as client:
        server.bind((CLOUD, PORT))
        client.sendto(b"hello", (CLOUD, PORT))
        server.settimeout(2)
        data, source = server.recvfrom(100)
        assert data == b"hello"
        assert source[0] == nat
        server.sendto(b"back", source)
        client.settimeout(2)
        assert client.recvfrom(100) == (b"back", (CLOUD, PORT))


@contextlib.contextmanager
def _robot_to_cloud_tcp(
    lab: Lab, timeout_s: float
) -> Iterator[tuple[socket.socket, socket.socket, tuple[str, int]]]:
    """A TCP connection from the robot to the cloud: its two ends and the source the cloud saw."""
    with lab.socket("cloud", socket.SOCK_STREAM) as listener:
        # The other TCP test's connection may still sit in TIME_WAIT on the same port.
        listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        listener.bind((CLOUD, PORT))
        listener.listen()
        listener.settimeout(timeout_s)
        with lab.socket("robot", socket.SOCK_STREAM) as client:
            client.settimeout(timeout_s)
            client.connect((CLOUD, PORT))
            accepted, source = listener.accept()
            with accepted:
                accepted.settimeout(timeout_s)
                yield client, accepted, source


def test_tcp_from_the_robot_arrives_from_its_nat(lab: Lab) -> None:
    with _robot_to_cloud_tcp(lab, timeout_s=2) as (client, accepted, source):
        client.sendall(b"ping")
        assert accepted.recv(4) == b"ping"
    assert source[0] == ROBOT_NAT


def test_the_cloud_cannot_reach_the_robot_private_address(lab: Lab) -> None:
    with lab.socket("robot") as robot, lab.socket("cloud") as cloud:
        robot.bind((lab.address("robot"), PORT))
        for _ in range(5):
            cloud.sendto(b"x", (lab.address("robot"), PORT))
        assert _drain(robot, 0.3) == []


def _within(count: int, sent: int, keep: float) -> bool:
    """``count`` of ``sent`` is within 6 standard deviations of a binomial with p = keep."""
    mean = sent * keep
    return abs(count - mean) <= 6 * math.sqrt(sent * keep * (1 - keep))


def test_loss_10_drops_about_a_tenth_each_way(lab: Lab) -> None:
    lab.apply("loss_10")
    sent = 3000
    uplink = downlink = 0
    with lab.socket("cloud") as server, lab.socket("robot") as client:
        server.bind((CLOUD, PORT))
        for batch in range(0, sent, 100):
            for i in range(batch, batch + 100):
                client.sendto(i.to_bytes(4, "big"), (CLOUD, PORT))
            # Echo what arrived, in small batches so no socket buffer overflows and the
            # only losses are the link's.
            arrived = _drain(server, 0.05)
            uplink += len(arrived)
            for data, source in arrived:
                server.sendto(data, source)
            downlink += len(_drain(client, 0.05))
    assert _within(uplink, sent, 0.9), uplink
    assert _within(downlink, uplink, 0.9), (uplink, downlink)


def test_clean_loses_nothing(lab: Lab) -> None:
    with lab.socket("cloud") as server, lab.socket("robot") as client:
        server.bind((CLOUD, PORT))
        for i in range(200):
            client.sendto(i.to_bytes(4, "big"), (CLOUD, PORT))
        assert len(_drain(server, 0.2)) == 200


def _binding(sock: socket.socket, server: tuple[str, int]) -> tuple[tuple[str, int], float]:
    request = stun.Message(message_method=stun.Method.BINDING, message_class=stun.Class.REQUEST)
    started = time.monotonic()
    sock.sendto(bytes(request), server)
    sock.settimeout(3)
    while True:
        data, _ = sock.recvfrom(2048)
        response = stun.parse_message(data)
        if response.transaction_id == request.transaction_id:
            return response.attributes["XOR-MAPPED-ADDRESS"], time.monotonic() - started


def test_rtt_150_sends_turn_traffic_through_the_delay_stage(lab: Lab) -> None:
    with lab.socket("robot") as sock:
        mapped, _ = _binding(sock, (CLOUD, TURN_PORT))
    # Clean: coturn sees the robot as its NAT.
    assert mapped[0] == ROBOT_NAT
    applied = lab.apply("rtt_150")
    with lab.socket("robot") as sock:
        rtts = []
        for _ in range(5):
            mapped, rtt = _binding(sock, (CLOUD, TURN_PORT))
            rtts.append(rtt)
    # Through the stage: coturn sees the stage's own upstream socket, in the cloud, and every
    # round trip took at least the configured round trip less its jitter.
    assert mapped[0] == CLOUD
    assert min(rtts) >= (applied.rtt_ms - applied.jitter_ms) / 1000, rtts


def test_link_drop_drops_everything_and_restores(lab: Lab) -> None:
    with lab.socket("cloud") as server, lab.socket("robot") as client:
        server.bind((CLOUD, PORT))
        client.sendto(b"before", (CLOUD, PORT))
        assert [d for d, _ in _drain(server, 0.2)] == [b"before"]
        with lab.outage():
            for _ in range(20):
                client.sendto(b"during", (CLOUD, PORT))
            server.sendto(b"down", (ROBOT_NAT, client.getsockname()[1]))
            assert _drain(server, 0.3) == []
            assert _drain(client, 0.3) == []
        client.sendto(b"after", (CLOUD, PORT))
        arrived = _drain(server, 0.3)
        assert [d for d, _ in arrived] == [b"after"]
        server.sendto(b"up", arrived[0][1])
        assert [d for d, _ in _drain(client, 0.3)] == [b"up"]


def test_unknown_condition_is_refused_by_name(lab: Lab) -> None:
    with pytest.raises(ValueError, match="unknown condition 'loss_99'.*clean"):
        lab.apply("loss_99")


def test_teardown_leaves_no_namespace_and_no_process() -> None:
    with Lab() as lab:
        names = set(lab.namespaces.values())
        assert names <= set(netns.list_names())
        coturn = next(p for p in lab._processes if "turnserver" in list(p.args))  # type: ignore[arg-type]
    assert names.isdisjoint(netns.list_names())
    assert coturn.poll() is not None


def test_a_dead_run_namespaces_are_removed_by_the_next_lab() -> None:
    gone = subprocess.Popen(["true"])
    gone.wait()
    stale = f"{netns.PREFIX}-{gone.pid}-beef-robot"
    netns.ip("netns", "add", stale)
    with Lab():
        assert stale not in netns.list_names()


def test_cap_1mbit_holds_the_robot_uplink_to_its_rate(lab: Lab) -> None:
    applied = lab.apply("cap_1mbit")
    payload = b"x" * 125_000  # one second's worth at 1 Mbit/s
    with _robot_to_cloud_tcp(lab, timeout_s=10) as (client, accepted, _):
        started = time.monotonic()
        client.sendall(payload)
        received = 0
        while received < len(payload):
            received += len(accepted.recv(65536))
        elapsed = time.monotonic() - started
    # A lower bound only: the bytes cannot cross faster than the cap (less the token bucket's
    # burst), however fast the machine is.
    assert elapsed >= 0.6 * len(payload) * 8 / (applied.uplink_kbit * 1000), elapsed
