"""tests/support/ports.py: the free-port helpers hand out loopback ports one can bind."""

from __future__ import annotations

import socket

import pytest

from tests.support import ports
from tests.support.ports import (
    free_port_block,
    free_tcp_port,
    free_udp_port,
    free_udp_ports,
    udp_sinks,
)


def test_free_tcp_port_can_be_bound_and_listened_on() -> None:
    port = free_tcp_port()
    assert 1024 <= port <= 65535
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", port))
        s.listen(1)


def test_free_udp_port_can_be_bound() -> None:
    port = free_udp_port()
    assert 1024 <= port <= 65535
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", port))


@pytest.mark.parametrize("kind", [socket.SOCK_DGRAM, socket.SOCK_STREAM])
def test_free_port_block_is_n_consecutive_bindable_ports(kind: int) -> None:
    n = 4
    base = free_port_block(n, kind)
    assert 20_000 <= base and base + n - 1 < 60_000
    socks = [socket.socket(socket.AF_INET, kind) for _ in range(n)]
    try:
        for i, s in enumerate(socks):
            s.bind(("127.0.0.1", base + i))
    finally:
        for s in socks:
            s.close()


def test_free_port_block_defaults_to_udp_and_rejects_an_empty_block() -> None:
    base = free_port_block(1)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", base))
    with pytest.raises(ValueError, match="n >= 1"):
        free_port_block(0)


def test_free_port_block_gives_up_when_every_probe_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    class TakenSocket:
        """Every bind fails as if the port were taken."""

        def __init__(self, *_: object) -> None:
            self.closed = False

        def bind(self, _address: tuple[str, int]) -> None:
            raise OSError("address already in use")

        def close(self) -> None:
            self.closed = True

    monkeypatch.setattr(ports.socket, "socket", TakenSocket)
    with pytest.raises(RuntimeError, match="no block of 2 free ports"):
        ports.free_port_block(2, tries=3)


def test_free_udp_ports_are_distinct_and_bindable() -> None:
    got = free_udp_ports(5)
    assert len(set(got)) == 5
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in got]
    try:
        for s, port in zip(socks, got, strict=True):
            s.bind(("127.0.0.1", port))
    finally:
        for s in socks:
            s.close()


def test_udp_sinks_hold_the_block_and_free_it_after() -> None:
    with udp_sinks(3) as base:
        for port in range(base, base + 3):
            with (
                socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s,
                pytest.raises(OSError, match="in use"),
            ):
                s.bind(("127.0.0.1", port))
    for port in range(base, base + 3):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", port))


def test_free_port_offsets_move_every_port_onto_free_ports_apart() -> None:
    tcp, udp = (7447, 8080), (14540, 14541, 14550, 18570)
    first, second = ports.free_port_offsets(tcp, udp, count=2, spacing=100)
    assert second == first + 100
    socks: list[socket.socket] = []
    try:
        for offset in (first, second):
            for bases, kind in ((tcp, socket.SOCK_STREAM), (udp, socket.SOCK_DGRAM)):
                for base in bases:
                    port = base + offset
                    assert ports.BLOCK_PORTS[0] <= port < ports.BLOCK_PORTS[1]
                    s = socket.socket(socket.AF_INET, kind)
                    socks.append(s)
                    s.bind((ports.LOOPBACK, port))
    finally:
        for s in socks:
            s.close()


def test_free_port_offsets_refuse_ports_spread_wider_than_the_blocks() -> None:
    with pytest.raises(RuntimeError, match="do not fit"):
        ports.free_port_offsets((1000,), (60000,))
