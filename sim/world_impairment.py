"""The world's lossy, late links (fault injection): the scenario's `impairment` section, or the
`--impair-link` flags, put on the vehicles' MAVLink and on the detections' Zenoh publications.

Each channel has its own generator from the impairment seed (the section's `seed`, else the
world's noise seed), named by what it carries: MAVLink (0, vehicle m, link 0 offboard / 1 GCS,
direction 0 up / 1 down), detections (1, UAV m). The same seed replays the same losses and
delays whatever the other channels carry. Truth and clock are never impaired: they are the
world's ground truth and time service, not radio traffic.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from isac_mission.config import ImpairmentConfig
from isac_mission.wire import Keys
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.link import VehicleLink
from sim.emulator import Publisher
from sim.impaired_io import DelayLine, ImpairedPublisher, wall_per_sim
from sim.impairment import ImpairedChannel, channel_rng

log = logging.getLogger(__name__)

LINK_INDEX = {"offboard": 0, "gcs": 1}
DIRECTION_INDEX = {"uplink": 0, "downlink": 1}


def vehicle_lines(
    impairment: ImpairmentConfig, seed: int, speed: float, m: int
) -> Callable[[VehicleLink, str], DelayLine | None]:
    """The `Autopilot.impair_links` factory of vehicle m: a DelayLine per impaired direction."""
    link_cfg = impairment.link_for(m)

    def make(link: VehicleLink, direction: str) -> DelayLine | None:
        cfg = link_cfg.uplink if direction == "uplink" else link_cfg.downlink
        if not cfg.active:
            return None
        rng = channel_rng(seed, 0, m, LINK_INDEX.get(link.name, 2), DIRECTION_INDEX[direction])
        deliver = link.receive if direction == "uplink" else link.sendto
        name = f"vehicle {m} {link.name} {direction}"
        return DelayLine(ImpairedChannel(cfg, rng), deliver, wall_per_sim(speed), name)

    return make


def impair_vehicles(
    vehicles: Sequence[Autopilot], impairment: ImpairmentConfig, seed: int, speed: float
) -> None:
    """Put each open vehicle's impairment on its links (nothing for unimpaired vehicles)."""
    for m, v in enumerate(vehicles):
        cfg = impairment.link_for(m)
        if cfg.active:
            v.impair_links(vehicle_lines(impairment, seed, speed, m))
            log.warning(
                "vehicle %d: impaired MAVLink (uplink %s; downlink %s)",
                m,
                describe(cfg.uplink.model_dump()),
                describe(cfg.downlink.model_dump()),
            )


def detection_publisher(
    bus: Publisher, keys: Keys, n_uavs: int, impairment: ImpairmentConfig, seed: int, speed: float
) -> ImpairedPublisher | None:
    """A publisher that carries every UAV's detections through its own channel (None when the
    detections are not impaired); other keys go straight to `bus`."""
    cfg = impairment.detections
    if not cfg.active:
        return None
    lines = {
        keys.detections(m): DelayLine(
            ImpairedChannel(cfg, channel_rng(seed, 1, m)),
            bus.publish,
            wall_per_sim(speed),
            f"detections {m}",
        )
        for m in range(n_uavs)
    }
    log.warning("impaired detections on Zenoh: %s", describe(cfg.model_dump()))
    return ImpairedPublisher(bus, lines)


def describe(fields: dict[str, float]) -> str:
    """`loss 0.2, latency 100 +- 50 ms, ...` of one channel's fields."""
    parts = [
        f"loss {fields['loss']:g}",
        f"latency {fields['latency_ms']:g} +- {fields['jitter_ms']:g} ms",
    ]
    if fields["duplicate"]:
        parts.append(f"duplicate {fields['duplicate']:g}")
    if fields["reorder"]:
        parts.append(f"reorder {fields['reorder']:g} (+{fields['reorder_delay_ms']:g} ms)")
    return ", ".join(parts)
