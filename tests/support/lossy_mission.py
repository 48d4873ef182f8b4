"""A live mission over lossy, late radio links, measured: the harness of
tests/reliability/test_lossy_links.py and bench/lossy_link.py.

`fly_lossy` flies `s` as `isac-mission run` does (the simulated world, the MAVLink bridges and
the ground loop in this process, over loopback UDP MAVLink and a real Zenoh session), with the
world built here (`sim.world.World`) so that every vehicle's offboard downlink can be watched:
for each heartbeat and each packet the vehicle offers to the radio, whether a copy arrived and
when (simulation time of sending + the channel's delay). From that it measures the longest radio
silence the bridge saw from each vehicle (between consecutive arrivals, heartbeats alone and any
packet), and from the trace how long each vehicle was excluded from the plan.

What "falsely excluded" means here: the bridge declares a vehicle's link lost after
`BridgeSettings.link_lost_after_s` (3 s) of silence from it, and the ground loop then plans
around it until it is back. An exclusion is warranted only by a silence longer than that; a
vehicle excluded without one, or for longer than the silence's excess plus `READMIT_ALLOWANCE_S`
(the re-entry into OFFBOARD and fresh telemetry), was falsely excluded.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import math
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from isac_mission.bus import BusSettings, tcp_loopback
from isac_mission.config import ImpairmentConfig, Scenario
from isac_mission.records import read_trace
from isac_mission.service.assembly import LiveOptions, run_serve
from isac_mission.service.mission_result import LiveResult, summarize_live
from sim.world import World
from sim.world_options import WorldOptions
from tests.support.ports import free_port_block, sitl_ports

HEARTBEAT_ID = 0
LINK_LOST_AFTER_S = 3.0
"""BridgeSettings.link_lost_after_s: the silence that makes the bridge declare a link lost."""
READMIT_ALLOWANCE_S = 4.0
"""Simulation seconds a vehicle whose radio is back may take to be planned again: heartbeat,
OFFBOARD re-entry, and fresh telemetry at the next slot boundary."""


def message_id(buf: bytes) -> int:
    """The MAVLink message id of one packed packet (v2 or v1); -1 if it is neither."""
    if len(buf) >= 10 and buf[0] == 0xFD:
        return buf[7] | buf[8] << 8 | buf[9] << 16
    if len(buf) >= 6 and buf[0] == 0xFE:
        return buf[5]
    return -1


@dataclass
class RadioWatch:
    """Arrival times (simulation s) at the bridge of one vehicle's offboard downlink."""

    heartbeats_sent: int = 0
    heartbeats_lost: int = 0
    arrivals_hb_s: list[float] = field(default_factory=list)
    arrivals_any_s: list[float] = field(default_factory=list)
    longest_hb_loss_run: int = 0
    _run: int = 0

    def observe(self, now_s: float, buf: bytes, delays_s: list[float]) -> None:
        """One packet offered at `now_s` with its copies' delays ([] lost)."""
        arrival = now_s + min(delays_s) if delays_s else None
        if arrival is not None:
            self.arrivals_any_s.append(arrival)
        if message_id(buf) != HEARTBEAT_ID:
            return
        self.heartbeats_sent += 1
        if arrival is None:
            self.heartbeats_lost += 1
            self._run += 1
            self.longest_hb_loss_run = max(self.longest_hb_loss_run, self._run)
        else:
            self._run = 0
            self.arrivals_hb_s.append(arrival)

    @staticmethod
    def _longest_gap(times: list[float], t0: float, t1: float) -> float:
        inside = sorted(t for t in times if t0 <= t <= t1)
        edges = [t0, *inside, t1]
        return max((b - a for a, b in itertools.pairwise(edges)), default=0.0)

    def longest_silence_s(self, t0: float, t1: float, heartbeats_only: bool) -> float:
        """Longest time between arrivals within [t0, t1] (simulation s); NaN if unwatched."""
        if self.heartbeats_sent == 0:
            return math.nan
        return self._longest_gap(
            self.arrivals_hb_s if heartbeats_only else self.arrivals_any_s, t0, t1
        )


@dataclass
class LossyRun:
    """One measured mission."""

    live: LiveResult
    completed: bool
    loc_rmse_m: float
    excluded_s: list[float]
    """Per vehicle: simulation seconds it was planned around (excluded slots x dt)."""
    hb_silence_s: list[float]
    """Per vehicle: the longest silence between heartbeats at the bridge during the mission."""
    any_silence_s: list[float]
    """Per vehicle: the longest silence between any two packets at the bridge."""
    hb_loss_run: list[int]
    """Per vehicle: the longest run of consecutive lost heartbeats (whole run)."""
    hb_loss_rate: float
    hb_sent: int
    """Heartbeats the vehicles offered to their offboard downlinks (the whole run)."""
    counters: dict[str, int]
    detections_lost: set[tuple[int, int]] = field(default_factory=set)
    """(slot, UAV) of every detection the world's impaired Zenoh channel lost."""
    detections_late_s: dict[tuple[int, int], float] = field(default_factory=dict)
    """(slot, UAV) -> the delay (simulation s) of each detection that got through."""

    def warranted_exclusion_s(self, m: int) -> float:
        """The exclusion vehicle m's radio silence warrants: the silence's excess over the link
        loss threshold, plus the readmission allowance (0 without such a silence)."""
        excess = self.any_silence_s[m] - LINK_LOST_AFTER_S
        return excess + READMIT_ALLOWANCE_S if excess > 0 else 0.0

    @property
    def falsely_excluded(self) -> list[int]:
        """Vehicles excluded for longer than their silence warrants."""
        return [
            m for m, t in enumerate(self.excluded_s) if t > self.warranted_exclusion_s(m) + 1e-9
        ]


async def fly_lossy(
    s: Scenario,
    out_dir: Path,
    *,
    impairment: ImpairmentConfig | None,
    seed: int = 1,
    speed: float = 4.0,
    lockstep: bool = True,
    **live: Any,
) -> LossyRun:
    """Fly `s` live once with `impairment` on the world's links (None: clean) and measure it;
    `live`: further LiveOptions."""
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    ports = sitl_ports(s.M)
    opts = LiveOptions(
        speed=speed,
        lockstep=lockstep,
        seed=seed,
        out_dir=out_dir,
        zenoh_endpoint=endpoint,
        **ports.world_kwargs(),
        **live,
    )
    world = World(
        s,
        WorldOptions(
            speed=speed,
            lockstep=lockstep,
            lockstep_timeout_s=60.0,
            seed=seed,
            bus=BusSettings(connect=(endpoint,)),
            **ports.world_kwargs(),
            start="offboard",
            impairment=impairment or ImpairmentConfig(),
        ),
    )
    watches = [RadioWatch() for _ in range(s.M)]
    detections_lost: set[tuple[int, int]] = set()
    detections_late: dict[tuple[int, int], float] = {}
    world_stop = asyncio.Event()

    def on_detection(args: tuple[Any, ...], delays: list[float]) -> None:
        msg = json.loads(args[1])
        key = (int(msg["slot"]), int(msg["uav"]))
        if delays:
            detections_late[key] = min(delays)
        else:
            detections_lost.add(key)

    async def run_world() -> None:
        try:
            await world.open()
            for m, v in enumerate(world.vehicles):
                line = v._links[0].downlink  # the offboard link's downlink
                if line is not None:
                    watch = watches[m]

                    def observe(
                        args: tuple[Any, ...], delays: list[float], w: RadioWatch = watch
                    ) -> None:
                        w.observe(world.clock.now_s, args[0], delays)

                    line.observer = observe
            if world.detection_links is not None:
                for line in world.detection_links.lines.values():
                    line.observer = on_detection
            await world.run(world_stop)
        finally:
            await world.close()

    task = asyncio.create_task(run_world())
    try:
        live = await run_serve(s, opts, asyncio.Event())
    finally:
        world_stop.set()
        await asyncio.wait_for(task, timeout=60.0)
    run = measure(s, live, world, watches)
    run.detections_lost, run.detections_late_s = detections_lost, detections_late
    return run


def measure(s: Scenario, live: LiveResult, world: World, watches: list[RadioWatch]) -> LossyRun:
    """The figures of one run (see LossyRun)."""
    trace = read_trace(live.trace_path)
    excluded = [0.0] * s.M
    for rec in trace.slots:
        for m in rec.extra.get("excluded", []):
            excluded[int(m)] += s.dt
    t0 = world.mission_t0_s if world.mission_t0_s is not None else 0.0
    t1 = t0 + s.N * s.dt
    sent = sum(w.heartbeats_sent for w in watches)
    lost = sum(w.heartbeats_lost for w in watches)
    counters = {**live.report.counters, **live.fleet_counters}
    slots = [r.slot for r in trace.slots]
    return LossyRun(
        live=live,
        completed=slots == list(range(1, s.N + 1))
        and live.fleet_counters.get("vehicles landed") == s.M,
        loc_rmse_m=summarize_live(live).loc_rmse,
        excluded_s=excluded,
        hb_silence_s=[w.longest_silence_s(t0, t1, heartbeats_only=True) for w in watches],
        any_silence_s=[w.longest_silence_s(t0, t1, heartbeats_only=False) for w in watches],
        hb_loss_run=[w.longest_hb_loss_run for w in watches],
        hb_loss_rate=lost / sent if sent else math.nan,
        hb_sent=sent,
        counters=counters,
    )
