"""Free loopback ports for the tests: the one helper family every test uses.

Every port is probed on 127.0.0.1 only (the network rule: nothing binds or sends elsewhere).
A port reported free was free a moment ago; another process may take it before the caller
binds it, so callers that can retry on `OSError` should.

- `free_tcp_port()`: one TCP port (a Zenoh `tcp/127.0.0.1:PORT` endpoint).
- `free_udp_port()`: one UDP port.
- `free_port_block(n, kind)`: a base port such that base .. base + n - 1 are all free (vehicle m
  uses base + m: MAVLink vehicle ports, ground-station ports).
"""

from __future__ import annotations

import random
import socket

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


def free_port_block(n: int, kind: int = socket.SOCK_DGRAM, tries: int = 200) -> int:
    """A base port such that base .. base + n - 1 were all free on 127.0.0.1 a moment ago.

    n: the block's length (>= 1); kind: socket.SOCK_DGRAM (UDP, the default) or
    socket.SOCK_STREAM (TCP); tries: random bases probed before giving up (RuntimeError).
    """
    if n < 1:
        raise ValueError(f"a port block needs n >= 1, got {n}")
    rng = random.Random()
    for _ in range(tries):
        base = rng.randrange(20_000, 60_000 - n)
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
