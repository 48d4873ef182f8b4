"""Lossy, late links on the event loop: the `sim.impairment` channel model put between a sender
and its receiver.

- `DelayLine`: one channel's packets, each passed to `deliver(*args)` after the delays the
  channel draws for it (simulation seconds, converted at the world's speed into wall seconds on
  the loop's timers), or never. The vehicles' MAVLink links put one on each direction
  (`sim.autopilot.link.VehicleLink.uplink` / `.downlink`, attached by
  `Autopilot.impair_links`).
- `ImpairedPublisher`: a bus publisher (`sim.emulator.Publisher`) that sends some keys through a
  DelayLine each (the world's detections, one channel per UAV) and the others at once.

Delays are simulation time; the world's nominal speed converts them (a held lockstep clock does
not hold the packets in flight, and an unpaced world, speed = inf, keeps loss and duplication
but delivers at once).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable, Mapping
from typing import Any

from sim.emulator import Publisher
from sim.impairment import ImpairedChannel

log = logging.getLogger(__name__)


def wall_per_sim(speed: float) -> float:
    """Wall seconds per simulation second at `speed` (0 for an unpaced world)."""
    return 1.0 / speed if math.isfinite(speed) and speed > 0 else 0.0


class DelayLine:
    """Carries calls `deliver(*args)` through `channel` (see the module docstring).

    Args:
        channel: Which copies arrive and after how long (simulation s).
        deliver: Called with the packet's arguments at each copy's arrival.
        wall_per_sim_s: Wall seconds per simulation second (`wall_per_sim(speed)`).
        name: For log messages.
    """

    def __init__(
        self,
        channel: ImpairedChannel,
        deliver: Callable[..., None],
        wall_per_sim_s: float,
        name: str = "",
    ) -> None:
        self.channel = channel
        self.name = name
        self._deliver = deliver
        self._scale = wall_per_sim_s
        self._pending: dict[int, asyncio.TimerHandle] = {}
        self._token = 0
        self._closed = False
        self.observer: Callable[[tuple[Any, ...], list[float]], None] | None = None
        """For measurements: called with each packet's arguments and its copies' delays
        (simulation s; [] when lost) as it is offered."""

    @property
    def in_flight(self) -> int:
        """Copies scheduled and not yet delivered."""
        return len(self._pending)

    def push(self, *args: Any) -> None:
        """Offer one packet (the arguments of `deliver`); its copies arrive later, or never."""
        if self._closed:
            return
        delays_s = self.channel.deliveries()
        if self.observer is not None:
            self.observer(args, delays_s)
        for delay_s in delays_s:
            wall_s = delay_s * self._scale
            if wall_s <= 0.0:
                self._call(None, args)
                continue
            self._token += 1
            handle = asyncio.get_running_loop().call_later(wall_s, self._call, self._token, args)
            self._pending[self._token] = handle

    def _call(self, token: int | None, args: tuple[Any, ...]) -> None:
        if token is not None:
            self._pending.pop(token, None)
        if self._closed:
            return
        try:
            self._deliver(*args)
        except Exception:  # a receiver's fault must not reach the loop's timer machinery
            log.exception("%s: delivery failed", self.name or "delay line")

    def close(self) -> None:
        """Drop every packet in flight; later pushes are dropped too (idempotent)."""
        self._closed = True
        for handle in self._pending.values():
            handle.cancel()
        self._pending.clear()


class ImpairedPublisher:
    """Publishes through `bus`, the keys of `lines` through their DelayLine (whose `deliver`
    is the bus's publish), every other key at once."""

    def __init__(self, bus: Publisher, lines: Mapping[str, DelayLine]) -> None:
        self._bus = bus
        self.lines = dict(lines)

    def publish(self, key: str, payload: bytes) -> None:
        """Put `payload` on `key`, through the key's channel if it has one."""
        line = self.lines.get(key)
        if line is None:
            self._bus.publish(key, payload)
        else:
            line.push(key, payload)

    def close(self) -> None:
        """Drop what is still in flight."""
        for line in self.lines.values():
            line.close()
