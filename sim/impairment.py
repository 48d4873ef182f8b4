"""The lossy, late radio channel, as a pure model: which copies of a packet arrive, and when.

`ImpairedChannel.deliveries()` draws, for one packet sent now, the delays (simulation seconds)
after which its copies arrive: `[]` lost, `[d]` once, `[d1, d2]` duplicated. Per packet,
independently, on the channel's own seeded generator, in this order:

1. lost with probability `loss` (then nothing else is drawn for it);
2. latency d ~ U[latency - jitter, latency + jitter];
3. held back with probability `reorder`: d += reorder_delay (the packets sent after it within
   that time overtake it); independent latencies reorder packets too, whenever two sent dt apart
   draw latencies more than dt apart;
4. duplicated with probability `duplicate`: a second copy with its own latency (step 2).

The same seed gives the same draws. Every sim/ link that carries packets through a channel
(`sim.impaired_io`) spawns one generator per vehicle, link and direction from the impairment
seed (`channel_rng`), so that the streams do not depend on each other's traffic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import ChannelImpairmentConfig

MS = 1e-3
"""Seconds per millisecond."""

IMPAIRMENT_STREAM = 0x1A1D
"""First word of the impairment seeds' entropy, so that they never equal the world's noise
streams (`SeedSequence(seed)`) of the same seed."""


@dataclass
class ChannelCounts:
    """What a channel did to the packets offered to it."""

    offered: int = 0
    lost: int = 0
    delivered: int = 0
    """Copies delivered (duplicates included)."""
    duplicated: int = 0
    held_back: int = 0


def channel_rng(seed: int, *path: int) -> np.random.Generator:
    """The generator of one channel: `path` names it (e.g. vehicle, link, direction)."""
    return np.random.default_rng(np.random.SeedSequence([IMPAIRMENT_STREAM, seed, *path]))


class ImpairedChannel:
    """One direction of one link (see the module docstring).

    Args:
        config: Loss, latency, jitter, duplication and reordering (ms of simulation time).
        rng: The channel's own generator (`channel_rng`).
    """

    def __init__(self, config: ChannelImpairmentConfig, rng: np.random.Generator) -> None:
        self.config = config
        self.counts = ChannelCounts()
        self._rng = rng
        self._latency_lo_s = (config.latency_ms - config.jitter_ms) * MS
        self._latency_hi_s = (config.latency_ms + config.jitter_ms) * MS

    @property
    def active(self) -> bool:
        """False when the channel passes every packet at once, unchanged."""
        return self.config.active

    def _latency_s(self) -> float:
        if self._latency_hi_s <= self._latency_lo_s:
            return self._latency_lo_s
        return float(self._rng.uniform(self._latency_lo_s, self._latency_hi_s))

    def deliveries(self) -> list[float]:
        """Delays (simulation s, >= 0) of the copies of one packet sent now; [] when lost."""
        c, counts = self.config, self.counts
        counts.offered += 1
        if c.loss and self._rng.random() < c.loss:
            counts.lost += 1
            return []
        delay_s = self._latency_s()
        if c.reorder and self._rng.random() < c.reorder:
            delay_s += c.reorder_delay_ms * MS
            counts.held_back += 1
        out = [delay_s]
        if c.duplicate and self._rng.random() < c.duplicate:
            out.append(self._latency_s())
            counts.duplicated += 1
        counts.delivered += len(out)
        return out
