"""Blocks of consecutive free loopback ports (vehicle m uses base + m)."""

from __future__ import annotations

import random
import socket


def free_port_block(n: int, kind: int = socket.SOCK_DGRAM, tries: int = 200) -> int:
    """A base port such that base .. base + n - 1 were all free on 127.0.0.1 a moment ago."""
    rng = random.Random()
    for _ in range(tries):
        base = rng.randrange(20_000, 60_000 - n)
        socks: list[socket.socket] = []
        try:
            for port in range(base, base + n):
                s = socket.socket(socket.AF_INET, kind)
                socks.append(s)
                s.bind(("127.0.0.1", port))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError(f"no block of {n} free ports found")
