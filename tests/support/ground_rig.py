"""A real GroundLoop over real Zenoh, with the test playing the world (tests/reliability).

`GroundRig`: the loop on a hub session and the test's world session connected to it, publishing
the clock and each UAV's detections, collecting the ground's plans, tracks and health;
`ground_rig_session`: the running rig; `Reference`: an independent EKF re-computation from the
first copy of each measurement that counts; `detections`: a slot's noisy detections of a target
at constant velocity. Nothing sleeps to synchronise: waits are on the ground's own messages.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.model.radar import measure
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.tracking.ekf import ekf_predict, ekf_update
from isac_mission.tracking.pcrb import SensingParams
from isac_mission.types import FloatArray, Gaussian
from isac_mission.wire import (
    ClockMsg,
    DetectionMsg,
    HealthMsg,
    Keys,
    PlanMsg,
    TrackMsg,
    decode,
    encode,
)
from tests.support.sim_harness import async_wait_until

WAIT_S = 30.0
"""Generous wall-clock bound for any single awaited event."""
N_SLOTS = 8
SEED = 7


@dataclass
class GroundRig:
    """A GroundLoop on a hub session and the test's world session connected to it."""

    s: Scenario
    keys: Keys
    world: ZenohBus
    loop: GroundLoop
    plans: dict[int, PlanMsg] = field(default_factory=dict)
    tracks: dict[int, TrackMsg] = field(default_factory=dict)
    health: list[HealthMsg] = field(default_factory=list)

    def publish_detection(self, msg: DetectionMsg) -> None:
        self.world.publish(self.keys.detections(msg.uav), encode(msg))

    def publish_raw(self, uav: int, payload: bytes) -> None:
        self.world.publish(self.keys.detections(uav), payload)

    def publish_clock(self, t_s: float) -> None:
        slot = int(np.floor(t_s / self.s.dt + 1e-9))
        msg = ClockMsg(slot=slot, t_s=t_s, slot_s=self.s.dt, speed=1.0, mission_t0_s=0.0)
        self.world.publish(self.keys.clock, encode(msg))

    async def start_mission(self) -> PlanMsg:
        """Announce mission start (t0 = 0) until plan 1 arrives, as the world's 10 Hz clock
        does: a single clock message could go out before the ground loop has subscribed (the
        world session's own collector already matches `clock`, so waiting for a subscriber
        does not tell)."""
        for _ in range(int(WAIT_S / 0.1)):
            self.publish_clock(0.0)
            with contextlib.suppress(TimeoutError):
                return await asyncio.wait_for(self.plan(1), 0.1)
        raise AssertionError(f"no plan 1 within {WAIT_S} s of announcing the mission start")

    async def plan(self, n: int) -> PlanMsg:
        await async_wait_until(lambda: n in self.plans, WAIT_S, f"plan {n}")
        return self.plans[n]

    async def track(self, n: int) -> TrackMsg:
        await async_wait_until(lambda: n in self.tracks, WAIT_S, f"track {n}")
        return self.tracks[n]

    async def until_counted(self, name: str, count: int) -> None:
        await async_wait_until(
            lambda: self.loop.report.counters[name] >= count, WAIT_S, f"{count} x {name!r}"
        )


async def collect(rig: GroundRig) -> None:
    async with rig.world.subscribe(rig.keys.everything) as sub:
        async for key, payload in sub:
            kind = key.rsplit("/", 1)[-1]
            if kind == "plan":
                p = decode(PlanMsg, payload)
                rig.plans[p.slot] = p
            elif kind == "track":
                t = decode(TrackMsg, payload)
                rig.tracks[t.slot] = t
            elif kind == "health":
                rig.health.append(decode(HealthMsg, payload))


@contextlib.asynccontextmanager
async def ground_rig_session(
    paper: Scenario, port: int, tmp_path: Path
) -> AsyncIterator[tuple[GroundRig, asyncio.Task[GroundReport]]]:
    """A running GroundLoop (N_SLOTS slots, trace in tmp_path) and the world session."""
    s = paper.with_changes(N=N_SLOTS)
    endpoint = tcp_loopback(port)
    keys = Keys(s.mission_id)
    stop = asyncio.Event()
    with (
        ZenohBus.open(BusSettings.hub(endpoint)) as ground_bus,
        ZenohBus.open(BusSettings(connect=(endpoint,))) as world,
    ):
        loop = GroundLoop(s, ground_bus, GroundSettings(trace_path=tmp_path / "trace.jsonl"))
        rig = GroundRig(s, keys, world, loop)
        collector = asyncio.create_task(collect(rig))
        assert await ground_bus.wait_for_subscribers(keys.plan, WAIT_S)
        run = asyncio.create_task(loop.run(stop))
        assert await world.wait_for_subscribers(keys.clock, WAIT_S)
        try:
            yield rig, run
        finally:
            stop.set()
            await asyncio.wait_for(run, WAIT_S)
            collector.cancel()


@dataclass
class Reference:
    """The independent re-computation: the EKF from x0, P0 with the measurements that count."""

    s: Scenario
    belief: Gaussian
    sens: SensingParams
    F: FloatArray
    W: FloatArray
    beliefs: dict[int, Gaussian] = field(default_factory=dict)

    @classmethod
    def start(cls, s: Scenario) -> Reference:
        return cls(
            s,
            Gaussian(s.x0.copy(), s.P0.copy()),
            SensingParams.from_scenario(s),
            transition_matrix(s.dt),
            process_noise(s.dt, s.kappa),
        )

    def step(self, n: int, used: list[DetectionMsg]) -> Gaussian:
        """Slot n with exactly the messages in `used` (one per UAV at most)."""
        m = self.s.M
        assert len({d.uav for d in used}) == len(used), "the reference takes each UAV once"
        pred = ekf_predict(self.belief, self.F, self.W)
        z = np.full(2 * m, np.nan)
        xy = np.array(self.s.uav_start_xy, dtype=float)
        eta = np.full(m, 1.0 / m)
        for d in used:
            z[d.uav], z[m + d.uav] = d.range_m, d.radial_velocity_mps
            xy[d.uav], eta[d.uav] = d.uav_xy_m, d.bandwidth_share
        r = self.sens.variances(np.linalg.norm(pred.x[None, :2] - xy, axis=1), eta)
        r = np.where(np.isfinite(z), r, np.nan)
        self.belief = ekf_update(pred, z, xy, r, self.s.ekf_iterations)
        self.beliefs[n] = self.belief
        return self.belief


def detections(
    s: Scenario, n: int, eta: FloatArray, rng: np.random.Generator
) -> list[DetectionMsg]:
    """Slot n's M detections of a target flying at constant velocity from x0 (noisy, seeded)."""
    F = transition_matrix(s.dt)
    x = np.linalg.matrix_power(F, n) @ s.x0
    xy = np.asarray(s.uav_start_xy, dtype=float)
    z = measure(x, xy)
    m = s.M
    noise = rng.normal(0.0, [2.0] * m + [0.5] * m)
    return [
        DetectionMsg(
            slot=n,
            t_s=n * s.dt,
            uav=u,
            range_m=float(z[u] + noise[u]),
            radial_velocity_mps=float(z[m + u] + noise[m + u]),
            uav_xy_m=xy[u].copy(),
            bandwidth_share=float(eta[u]),
        )
        for u in range(m)
    ]


def payload_with(msg: DetectionMsg, **fields: object) -> bytes:
    """msg's payload with some fields replaced, NaN written as the bare token (not valid JSON)."""
    obj = json.loads(encode(msg)) | fields
    return json.dumps(obj, allow_nan=True).encode()


def assert_same_belief(track: TrackMsg, ref: Gaussian, what: str) -> None:
    np.testing.assert_allclose(track.x, ref.x, rtol=1e-9, atol=1e-9, err_msg=f"{what}: x")
    np.testing.assert_allclose(track.P, ref.P, rtol=1e-9, atol=1e-12, err_msg=f"{what}: P")
