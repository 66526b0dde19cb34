"""The field lab: three sites behind real NATs, with TURN, built from namespaces.

::

    robot 192.168.10.2 ── rnat ──┐                ┌── onat ── operator 192.168.20.2
      (eth0)      (lan0)  (wan0) │  wan (bridge)  │ (wan0)  (lan0)      (eth0)
                      172.30.0.2 ├───────┬────────┤ 172.30.0.3
                                         │ wan's own 172.30.0.1: the default gateway
                                         │ (routes nowhere further)
                                  cloud 172.30.0.10 (server, coturn, relay)

Every box is a network namespace; ``rnat`` and ``onat`` forward and masquerade (nftables), so the
cloud sees the robot and the operator as their routers' public addresses, and the robot and the
operator reach each other only by punching through both NATs or through TURN. The robot's link
(robot eth0 <-> rnat lan0) carries the named conditions (:mod:`.conditions`).

Use :class:`Lab` as a context manager: it builds on entry and always tears down on exit (processes
it started, then its namespaces). Conditions change flows only for connections made after they
are applied (NAT and DNAT decisions are cached per connection by conntrack).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import secrets
import shlex
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from aioice import stun

import app
from app.server.turn import IceTransportPolicy
from app.supervise import stop_process
from app.tools.lab import coturn, netns
from app.tools.lab.conditions import Condition, condition

log = logging.getLogger(__name__)

SITES = ("cloud", "robot", "operator")
ROUTERS = ("wan", "rnat", "onat")

CLOUD = "172.30.0.10"
INTERNET_GATEWAY = "172.30.0.1"
PUBLIC_PREFIX = 24
ROBOT_NAT = "172.30.0.2"
OPERATOR_NAT = "172.30.0.3"
ROBOT = "192.168.10.2"
ROBOT_GATEWAY = "192.168.10.1"
OPERATOR = "192.168.20.2"
OPERATOR_GATEWAY = "192.168.20.1"
LAN_PREFIX = 24
DELAY_PORT = coturn.TURN_PORT + 1
UPLINK_BURST_KBIT = 32
UPLINK_QUEUE_MS = 100
READY_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class Site:
    """A place processes run: its namespace and its own address."""

    name: str
    namespace: str
    address: str


class Lab:
    """Builds the lab on ``__enter__``, tears it down on ``__exit__``."""

    def __init__(self) -> None:
        tag = secrets.token_hex(2)
        self.run_id = f"{netns.PREFIX}-{os.getpid()}-{tag}"
        self.namespaces = {name: f"{self.run_id}-{name}" for name in (*SITES, *ROUTERS)}
        self.sites = {
            "cloud": Site("cloud", self.namespaces["cloud"], CLOUD),
            "robot": Site("robot", self.namespaces["robot"], ROBOT),
            "operator": Site("operator", self.namespaces["operator"], OPERATOR),
        }
        self.turn_secret = secrets.token_urlsafe(24)
        self.turn_url = f"turn:{CLOUD}:{coturn.TURN_PORT}?transport=udp"
        self.stun_url = f"stun:{CLOUD}:{coturn.TURN_PORT}"
        self.condition = condition("clean")
        self._workdir: Path | None = None
        self._processes: list[subprocess.Popen[Any]] = []
        self._delay: subprocess.Popen[str] | None = None
        self._built: list[str] = []

    # -- building and tearing down -------------------------------------------------------------

    def __enter__(self) -> Lab:
        netns.remove_stale()
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _build(self) -> None:
        self._workdir = Path(tempfile.mkdtemp(prefix=f"{self.run_id}-"))
        for name in self.namespaces.values():
            netns.ip("netns", "add", name)
            self._built.append(name)
            # No IPv6 link-local addresses on the links made next: they would appear seconds
            # later (duplicate address detection), and Chromium fails the requests in flight
            # at that moment with ERR_NETWORK_CHANGED.
            netns.run_checked(
                netns.exec_argv(name, ["sysctl", "-qw", "net.ipv6.conf.default.addr_gen_mode=1"])
            )
            netns.ip("link", "set", "lo", "up", namespace=name)
        ns = self.namespaces
        netns.ip("link", "add", "br0", "type", "bridge", namespace=ns["wan"])
        self._address(ns["wan"], "br0", INTERNET_GATEWAY, PUBLIC_PREFIX)
        for host, address in (("cloud", CLOUD), ("rnat", ROBOT_NAT), ("onat", OPERATOR_NAT)):
            port = f"to-{host}"
            self._veth(ns["wan"], port, ns[host], "wan0")
            netns.ip("link", "set", port, "master", "br0", "up", namespace=ns["wan"])
            self._address(ns[host], "wan0", address, PUBLIC_PREFIX)
            # Chromium gathers no candidates at all on a host without a default route.
            netns.ip("route", "add", "default", "via", INTERNET_GATEWAY, namespace=ns[host])
        for router, lan_site, gateway, address in (
            ("rnat", "robot", ROBOT_GATEWAY, ROBOT),
            ("onat", "operator", OPERATOR_GATEWAY, OPERATOR),
        ):
            self._veth(ns[router], "lan0", ns[lan_site], "eth0")
            self._address(ns[router], "lan0", gateway, LAN_PREFIX)
            self._address(ns[lan_site], "eth0", address, LAN_PREFIX)
            netns.ip("route", "add", "default", "via", gateway, namespace=ns[lan_site])
            netns.run_checked(
                netns.exec_argv(ns[router], ["sysctl", "-qw", "net.ipv4.ip_forward=1"])
            )
            netns.nft(
                ns[router],
                "table ip lab_nat {\n"
                "  chain postrouting {\n"
                "    type nat hook postrouting priority srcnat;\n"
                '    oifname "wan0" masquerade\n'
                "  }\n"
                "}\n",
            )
        self._start_coturn()
        log.info("lab %s built", self.run_id)

    @staticmethod
    def _veth(ns_a: str, name_a: str, ns_b: str, name_b: str) -> None:
        # Both ends are created straight inside their namespaces: nothing appears, even for a
        # moment, in the namespace the lab runs from.
        netns.ip(
            "link", "add", "name", name_a, "netns", ns_a,
            "type", "veth", "peer", "name", name_b, "netns", ns_b,
        )  # fmt: skip

    @staticmethod
    def _address(namespace: str, device: str, address: str, prefix: int) -> None:
        netns.ip("addr", "add", f"{address}/{prefix}", "dev", device, namespace=namespace)
        netns.ip("link", "set", device, "up", namespace=namespace)

    def _start_coturn(self) -> None:
        assert self._workdir is not None
        path = coturn.write_config(self._workdir, CLOUD, self.turn_secret)
        self.popen(
            "cloud",
            coturn.argv(path),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + READY_TIMEOUT_S
        with contextlib.closing(self.socket("cloud")) as sock:
            sock.settimeout(0.2)
            while True:
                if _stun_binding(sock, (CLOUD, coturn.TURN_PORT)) is not None:
                    return
                if time.monotonic() > deadline:
                    log_path = self._workdir / "turnserver.log"
                    tail = log_path.read_text()[-2000:] if log_path.exists() else "(no log)"
                    raise netns.LabError(f"coturn did not answer within {READY_TIMEOUT_S}s: {tail}")

    def close(self) -> None:
        """Stop every process the lab started and delete its namespaces; safe to call twice."""
        for process in reversed(self._processes):
            _stop(process)
        self._processes.clear()
        self._delay = None
        for name in reversed(self._built):
            netns.delete(name)
        self._built.clear()
        if self._workdir is not None:
            shutil.rmtree(self._workdir, ignore_errors=True)
            self._workdir = None

    # -- running things in sites ---------------------------------------------------------------

    def namespace(self, site: str) -> str:
        """The namespace of a site or router; an unknown name is a ValueError."""
        try:
            return self.namespaces[site]
        except KeyError:
            raise ValueError(
                f"unknown site {site!r}; known: {', '.join(self.namespaces)}"
            ) from None

    def address(self, site: str) -> str:
        """The site's own address (cloud's is public; robot's and operator's are private)."""
        return self.sites[site].address

    def argv(self, site: str, argv: Sequence[str]) -> list[str]:
        """The argv that runs ``argv`` inside ``site``."""
        return netns.exec_argv(self.namespace(site), argv)

    def env(self) -> dict[str, str]:
        """An environment for Python processes in sites: they import this very ``app``."""
        root = str(Path(app.__file__).resolve().parent.parent)
        path = os.environ.get("PYTHONPATH")
        return {**os.environ, "PYTHONPATH": f"{root}{os.pathsep}{path}" if path else root}

    def run(
        self, site: str, argv: Sequence[str], **kwargs: Any
    ) -> subprocess.CompletedProcess[Any]:
        """``subprocess.run`` inside ``site``."""
        kwargs.setdefault("env", self.env())
        return subprocess.run(self.argv(site, argv), **kwargs)

    def popen(self, site: str, argv: Sequence[str], **kwargs: Any) -> subprocess.Popen[Any]:
        """``subprocess.Popen`` inside ``site``; the lab stops it on teardown."""
        kwargs.setdefault("env", self.env())
        process: subprocess.Popen[Any] = subprocess.Popen(self.argv(site, argv), **kwargs)
        self._processes.append(process)
        return process

    def python(self, site: str, args: Sequence[str], **kwargs: Any) -> subprocess.Popen[Any]:
        """Start ``python3 ARGS`` inside ``site`` (with this ``app`` importable)."""
        return self.popen(site, [sys.executable, *args], **kwargs)

    def socket(self, site: str, kind: socket.SocketKind = socket.SOCK_DGRAM) -> socket.socket:
        """An IPv4 socket in ``site``, for this process to talk from there."""
        return netns.open_socket(self.namespace(site), kind)

    def stop(self, process: subprocess.Popen[Any]) -> None:
        """Stop a process started with :meth:`popen` before the lab goes down."""
        _stop(process)
        if process in self._processes:
            self._processes.remove(process)

    def wait_for_tcp(
        self,
        site: str,
        address: tuple[str, int],
        timeout_s: float = 60.0,
        server: subprocess.Popen[Any] | None = None,
    ) -> None:
        """Return once ``address`` accepts TCP connections from ``site``; raise at once when
        ``server``, the process that is to listen there, has exited."""
        deadline = time.monotonic() + timeout_s
        while True:
            if server is not None and server.poll() is not None:
                raise netns.LabError(f"the server for {address} exited with {server.returncode}")
            with contextlib.closing(self.socket(site, socket.SOCK_STREAM)) as sock:
                sock.settimeout(1)
                try:
                    sock.connect(address)
                    return
                except OSError as exc:
                    if time.monotonic() > deadline:
                        raise netns.LabError(f"{address} unreachable from {site}: {exc}") from exc
            time.sleep(0.2)

    def chromium(self, site: str, executable: str) -> Path:
        """A launcher that runs ``executable`` (Chromium) inside ``site``, for Playwright's
        ``executable_path``: Playwright talks to the browser over pipes, so it need not be in
        the site itself."""
        assert self._workdir is not None
        path = self._workdir / f"chromium-{site}"
        path.write_text(
            f'#!/bin/sh\nexec ip netns exec {self.namespace(site)} {shlex.quote(executable)} "$@"\n'
        )
        path.chmod(0o755)
        return path

    def server_env(self, policy: IceTransportPolicy | None = None) -> dict[str, str]:
        """Environment for ``autopilot serve`` in the cloud: the lab's STUN and TURN (shared
        secret), and the ICE policy (the current condition's unless given)."""
        return {
            **self.env(),
            "AUTOPILOT_STUN_URLS": json.dumps([self.stun_url]),
            "AUTOPILOT_TURN_URLS": json.dumps([self.turn_url]),
            "AUTOPILOT_TURN_SECRET": self.turn_secret,
            "AUTOPILOT_ICE_TRANSPORT_POLICY": policy or self.condition.ice_transport_policy,
        }

    # -- conditions ----------------------------------------------------------------------------

    def apply(self, name: str) -> Condition:
        """Put the named condition on the robot's link (replacing the previous one)."""
        wanted = condition(name)
        ns = self.namespaces
        self._clear_conditions()
        if wanted.loss_percent:
            drop = f"numgen random mod 100 < {wanted.loss_percent} drop"
            self._on_robot_link("lab_loss", drop)
        if wanted.uplink_kbit:
            netns.run_checked(
                netns.exec_argv(
                    ns["robot"],
                    [
                        "tc", "qdisc", "replace", "dev", "eth0", "root", "tbf",
                        "rate", f"{wanted.uplink_kbit}kbit",
                        "burst", f"{UPLINK_BURST_KBIT}kbit",
                        "latency", f"{UPLINK_QUEUE_MS}ms",
                    ],
                )
            )  # fmt: skip
        if wanted.rtt_ms:
            self._start_delay(wanted.rtt_ms / 2, wanted.jitter_ms / 2)
        self.condition = wanted
        log.info("lab condition: %s (%s)", wanted.name, wanted.description)
        return wanted

    def set_robot_link(self, up: bool) -> None:
        """Drop every packet on the robot's link (``up=False``) or let them through again."""
        if up:
            self._delete_table(self.namespaces["robot"], "netdev", "lab_outage")
            self._delete_table(self.namespaces["rnat"], "netdev", "lab_outage")
        else:
            self._on_robot_link("lab_outage", "drop")

    @contextlib.contextmanager
    def outage(self) -> Iterator[None]:
        """The robot's link is dark inside the block."""
        self.set_robot_link(False)
        try:
            yield
        finally:
            self.set_robot_link(True)

    def _on_robot_link(self, table: str, rule: str) -> None:
        # Both ends' ingress: the robot's for traffic to it, the router's for traffic from it.
        # A drop on ingress is silent to the sender, as a lossy link is (an output-hook drop
        # would hand the sender EPERM instead).
        for site, device in (("robot", "eth0"), ("rnat", "lan0")):
            netns.nft(
                self.namespaces[site],
                f"table netdev {table} {{\n"
                "  chain ingress {\n"
                f'    type filter hook ingress device "{device}" priority filter;\n'
                f"    {rule}\n"
                "  }\n"
                "}\n",
            )

    def _clear_conditions(self) -> None:
        ns = self.namespaces
        for site in ("robot", "rnat"):
            self._delete_table(ns[site], "netdev", "lab_loss")
        self._delete_table(ns["rnat"], "ip", "lab_delay")
        subprocess.run(
            netns.exec_argv(ns["robot"], ["tc", "qdisc", "del", "dev", "eth0", "root"]),
            capture_output=True,
            check=False,
        )  # absent when no cap was set
        if self._delay is not None:
            _stop(self._delay)
            self._processes.remove(self._delay)
            self._delay = None

    @staticmethod
    def _delete_table(namespace: str, family: str, table: str) -> None:
        # Declaring the table first makes the delete succeed whether or not it existed.
        netns.nft(namespace, f"table {family} {table}\ndelete table {family} {table}\n")

    def _start_delay(self, one_way_ms: float, jitter_ms: float) -> None:
        """The delay stage in the cloud, and the robot's TURN traffic steered through it."""
        process = self.python(
            "cloud",
            [
                "-m", "app.tools.lab.delay",
                "--listen", f"{CLOUD}:{DELAY_PORT}",
                "--upstream", f"{CLOUD}:{coturn.TURN_PORT}",
                "--delay-ms", str(one_way_ms),
                "--jitter-ms", str(jitter_ms),
            ],
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        self._delay = process
        assert process.stdout is not None
        if process.stdout.readline().strip() != "ready":
            raise netns.LabError(f"delay stage did not start (exit {process.poll()})")
        netns.nft(
            self.namespaces["rnat"],
            "table ip lab_delay {\n"
            "  chain prerouting {\n"
            "    type nat hook prerouting priority dstnat;\n"
            f'    iifname "lan0" ip daddr {CLOUD} udp dport {coturn.TURN_PORT}'
            f" dnat to {CLOUD}:{DELAY_PORT}\n"
            "  }\n"
            "}\n",
        )


def _stop(process: subprocess.Popen[Any]) -> None:
    stop_process(process, grace_s=3)
    for pipe in (process.stdin, process.stdout, process.stderr):
        if pipe is not None:
            pipe.close()


def _stun_binding(sock: socket.socket, server: tuple[str, int]) -> tuple[str, int] | None:
    """One STUN Binding request; the mapped address, or None when nothing answered in time."""
    request = stun.Message(message_method=stun.Method.BINDING, message_class=stun.Class.REQUEST)
    sock.sendto(bytes(request), server)
    try:
        data, _ = sock.recvfrom(2048)
    except (TimeoutError, ConnectionRefusedError):
        return None
    response = stun.parse_message(data)
    mapped: tuple[str, int] = response.attributes["XOR-MAPPED-ADDRESS"]
    return mapped
