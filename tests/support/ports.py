"""Free loopback ports for the tests: the one helper family every test uses.

Every port is probed on 127.0.0.1 only (the network rule: nothing binds or sends elsewhere).
A port reported free was free a moment ago; another process may take it before the caller
binds it, so callers that can retry on `OSError` should.

- `free_tcp_port()`: one TCP port (a Zenoh `tcp/127.0.0.1:PORT` endpoint).
- `free_udp_port()`: one UDP port.
- `free_udp_ports(n)`: n distinct UDP ports (not necessarily consecutive).
- `free_port_block(n, kind)`: a base port such that base .. base + n - 1 are all free (vehicle m
  uses base + m: MAVLink vehicle ports, ground-station ports).
- `sitl_ports(n)`: a `SitlPorts`, PX4 SITL's four port families (offboard and ground-station
  destinations, and the vehicles' local ports) on free ports, as `WorldOptions` / `LiveOptions`
  keyword arguments (`world_kwargs()`) or CLI options (`cli_args()`);
  `sitl_ports_and_blocks(n, sizes)` with further blocks none of which overlaps another
  (`disjoint_port_blocks`).
- `free_port_offsets(tcp, udp, count)`: offsets that move a set of ports (a mission's, at
  `--port-offset 0`) onto free ports, for `--port-offset`.
- `udp_sinks(n)`: n consecutive UDP ports bound (and so kept) for the duration of a `with` block,
  for a test that must receive what vehicles send to base + m; yields the base.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import random
import socket
from collections.abc import Iterator

LOOPBACK = "127.0.0.1"
"""The only address the tests bind to."""


def _free_port(kind: int) -> int:
    """A port of socket type `kind` (SOCK_STREAM or SOCK_DGRAM) the kernel reports free."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind((LOOPBACK, 0))
        return int(s.getsockname()[1])


def free_tcp_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    return _free_port(socket.SOCK_STREAM)


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that was free a moment ago."""
    return _free_port(socket.SOCK_DGRAM)


def free_udp_ports(n: int) -> list[int]:
    """`n` distinct UDP ports on 127.0.0.1 that were free a moment ago (all probed at once, so no
    port is handed out twice)."""
    socks: list[socket.socket] = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            socks.append(s)
            s.bind((LOOPBACK, 0))
        return [int(s.getsockname()[1]) for s in socks]
    finally:
        for s in socks:
            s.close()


BLOCK_PORTS = (20_000, 32_000)
"""Where port blocks are drawn: below Linux's ephemeral range (32768-60999), so that no port the
kernel hands out (a `bind(0)`, an outgoing connection's local port) falls in a block."""
MAX_WORKERS = 4
"""Parallel test workers (pytest-xdist) that get their own slice of BLOCK_PORTS."""


def _block_range() -> tuple[int, int]:
    """This process's slice of BLOCK_PORTS: pytest-xdist worker gwK draws its blocks from slice
    K mod MAX_WORKERS, so that two workers never probe the same block at once."""
    low, high = BLOCK_PORTS
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if not worker.startswith("gw"):
        return low, high
    width = (high - low) // MAX_WORKERS
    k = int(worker[2:]) % MAX_WORKERS
    return low + k * width, low + (k + 1) * width


def free_port_block(n: int, kind: int = socket.SOCK_DGRAM, tries: int = 200) -> int:
    """A base port such that base .. base + n - 1 were all free on 127.0.0.1 a moment ago.

    n: the block's length (>= 1); kind: socket.SOCK_DGRAM (UDP, the default) or
    socket.SOCK_STREAM (TCP); tries: random bases probed before giving up (RuntimeError).
    """
    if n < 1:
        raise ValueError(f"a port block needs n >= 1, got {n}")
    rng = random.Random()
    low, high = _block_range()
    for _ in range(tries):
        base = rng.randrange(low, high - n)
        socks: list[socket.socket] = []
        try:
            for port in range(base, base + n):
                s = socket.socket(socket.AF_INET, kind)
                socks.append(s)
                s.bind((LOOPBACK, port))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError(f"no block of {n} free ports found")


@contextlib.contextmanager
def udp_sinks(n: int, tries: int = 50) -> Iterator[int]:
    """Bind n consecutive UDP ports on 127.0.0.1 and keep them bound inside the `with` block;
    yields the first. Nothing is read from them: they only make the ports taken (a vehicle's
    datagrams to base + m are not refused). RuntimeError after `tries` failed blocks."""
    for _ in range(tries):
        base = free_port_block(n)
        socks: list[socket.socket] = []
        try:
            for port in range(base, base + n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind((LOOPBACK, port))
        except OSError:  # taken between the probe and the bind: another block
            for s in socks:
                s.close()
            continue
        try:
            yield base
        finally:
            for s in socks:
                s.close()
        return
    raise RuntimeError(f"no block of {n} free UDP ports")


@dataclasses.dataclass(frozen=True)
class SitlPorts:
    """PX4 SITL's MAVLink port layout on free ports (docs/service.md, "Ports"): vehicle m sends its
    offboard link from `offboard_local_base + m` to `offboard_base + m` and its ground-station
    link from `gcs_local_base + m` to `gcs` (one port for the fleet)."""

    offboard_base: int
    offboard_local_base: int
    gcs: int
    gcs_local_base: int

    def world_kwargs(self) -> dict[str, int]:
        """The port fields of `WorldOptions` and `LiveOptions`."""
        return {
            "mavlink_base_port": self.offboard_base,
            "mavlink_local_base_port": self.offboard_local_base,
            "gcs_port": self.gcs,
            "gcs_local_base_port": self.gcs_local_base,
        }

    def cli_args(self) -> list[str]:
        """The port options of `isac-mission run` / `sim`."""
        return [
            "--mavlink-base-port",
            str(self.offboard_base),
            "--mavlink-local-base-port",
            str(self.offboard_local_base),
            "--gcs-port",
            str(self.gcs),
            "--gcs-local-base-port",
            str(self.gcs_local_base),
        ]


def disjoint_port_blocks(sizes: tuple[int, ...], tries: int = 50) -> list[int]:
    """Bases of UDP blocks of the given sizes in BLOCK_PORTS (below the ephemeral range), that
    do not overlap and were all free at once a moment ago. RuntimeError after `tries` attempts."""
    for _ in range(tries):
        bases = [free_port_block(n) for n in sizes]
        socks: list[socket.socket] = []
        try:
            for base, n in zip(bases, sizes, strict=True):
                for port in range(base, base + n):
                    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                    socks.append(s)
                    s.bind((LOOPBACK, port))
        except OSError:  # two blocks overlap, or a port was taken meanwhile
            continue
        finally:
            for s in socks:
                s.close()
        return bases
    raise RuntimeError(f"no {len(sizes)} disjoint free UDP port blocks of sizes {sizes}")


def sitl_ports(n: int, tries: int = 50) -> SitlPorts:
    """Free, non-overlapping UDP ports for a fleet of n vehicles in PX4 SITL's layout (three blocks
    of n and one single port, all probed bound at once, all below the ephemeral range).
    RuntimeError after `tries` attempts."""
    return sitl_ports_and_blocks(n, (), tries)[0]


def sitl_ports_and_blocks(
    n: int, sizes: tuple[int, ...], tries: int = 50
) -> tuple[SitlPorts, list[int]]:
    """`sitl_ports(n)` and further blocks of `sizes` (e.g. a service's own bridge ports), none
    overlapping another."""
    offboard, offboard_local, gcs_local, gcs, *more = disjoint_port_blocks(
        (n, n, n, 1, *sizes), tries
    )
    return SitlPorts(offboard, offboard_local, gcs, gcs_local), more


def free_port_offsets(
    tcp: tuple[int, ...], udp: tuple[int, ...], count: int = 1, spacing: int = 100, tries: int = 50
) -> list[int]:
    """`count` port offsets N, N + spacing, ... (`isac-mission run --port-offset`) such that
    every port p + offset, for p in `tcp` (TCP) and in `udp` (UDP), lies in BLOCK_PORTS (below
    the ephemeral range) and all were free at once a moment ago. RuntimeError when BLOCK_PORTS
    cannot hold the spread of the ports, or after `tries` attempts."""
    every = (*tcp, *udp)
    low = BLOCK_PORTS[0] - min(every)
    high = BLOCK_PORTS[1] - 1 - max(every) - spacing * (count - 1)
    if low > high:
        raise RuntimeError(f"ports {min(every)}..{max(every)} do not fit in {BLOCK_PORTS}")
    rng = random.Random()
    for _ in range(tries):
        first = rng.randint(low, high)
        offsets = [first + k * spacing for k in range(count)]
        socks: list[socket.socket] = []
        try:
            for offset in offsets:
                for ports, kind in ((tcp, socket.SOCK_STREAM), (udp, socket.SOCK_DGRAM)):
                    for port in ports:
                        s = socket.socket(socket.AF_INET, kind)
                        socks.append(s)
                        s.bind((LOOPBACK, port + offset))
        except OSError:  # taken, or two offsets' ports overlap
            continue
        finally:
            for s in socks:
                s.close()
        return offsets
    raise RuntimeError(f"no {count} free port offsets for TCP {tcp} and UDP {udp}")


def listening_hosts() -> set[str]:
    """IP addresses of every listening or unconnected inet socket of this process and its
    children (psutil)."""
    import psutil

    me = psutil.Process()
    hosts: set[str] = set()
    for proc in [me, *me.children(recursive=True)]:
        for conn in proc.net_connections(kind="inet"):
            if conn.status == psutil.CONN_LISTEN or not conn.raddr:
                hosts.add(conn.laddr.ip)
    return hosts
