"""An operator takes a vehicle from a real MAVProxy during a live mission, and gives it back.

Real parts: the embedded world's PX4-like vehicles over loopback UDP MAVLink (PX4 SITL's port
layout), the bridges and the ground loop of `run`, a real MAVProxy process on the fleet's
ground-station port, and a Zenoh observer (plans, telemetry, health, control replies).

MAVProxy switches vehicle 1 (system id 2) to HOLD (PX4 AUTO.LOITER) with the command a ground
station sends (MAV_CMD_DO_SET_MODE; tests/support/mavproxy.py says why not MAVProxy's `mode`).
The service must then leave it alone: it stays in HOLD for 10 s of simulation time, the plans
leave it out (share 0, no BS) with the others at least D_s from its live position, and `health`
says "operator: HOLD". MAVProxy switches it back to OFFBOARD: it is planned again. A second HOLD
is ended by an operator's `release` on `control` instead: the bridge takes it back itself.
"""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path

import numpy as np

from isac_mission.bus import ZenohBus, tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import Scenario
from isac_mission.mavwire.modes import FlightMode
from isac_mission.service.assembly import LiveOptions
from isac_mission.wire import Keys, PlanMsg
from tests.support.mavproxy import MavlinkListener, MavProxy
from tests.support.mission_watch import MissionWatch, open_client
from tests.support.ports import free_port_block, sitl_ports

TAKEN = 1
"""The vehicle index the operator takes (system id 2)."""
HOLD_S = 10.0
"""Simulation seconds it must stay in HOLD, untouched by the service."""
WAIT_S = 240.0
"""Generous wall-clock bound of every wait (a loaded 2-core machine)."""


def _excluded(plan: PlanMsg, m: int) -> bool:
    return int(plan.plan.bs_of_uav[m]) == -1 and float(plan.plan.bandwidth_share[m]) == 0.0


def _planned(plan: PlanMsg, m: int) -> bool:
    return int(plan.plan.bs_of_uav[m]) >= 0 and float(plan.plan.bandwidth_share[m]) > 0.0


async def _mode_set(mp: MavProxy, sysid: int, mode: FlightMode) -> None:
    mark = mp.set_px4_mode(sysid, mode)
    await asyncio.to_thread(mp.wait_for, r"DO_SET_MODE: ACCEPTED", 60.0, mark)


async def test_an_operators_hold_from_mavproxy_is_respected_and_handed_back(
    paper: Scenario, tmp_path: Path
) -> None:
    s = paper.with_changes(N=90, H=20.0)  # a low altitude: a short climb and landing
    keys = Keys(s.mission_id)
    ports = sitl_ports(s.M)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    opts = LiveOptions(
        speed=5.0,
        lockstep=True,
        seed=3,
        out_dir=tmp_path,
        zenoh_endpoint=endpoint,
        **ports.world_kwargs(),
    )
    stop = asyncio.Event()
    with (
        MavlinkListener() as seen,
        MavProxy(f"udpin:127.0.0.1:{ports.gcs}", [seen.out]) as mp,
    ):
        mission = asyncio.create_task(run_embedded(s, opts, stop))
        try:
            with await open_client(endpoint, WAIT_S) as observer:
                await _fly(s, keys, seen, mp, observer)
        finally:
            stop.set()
            result = await asyncio.wait_for(mission, timeout=WAIT_S)
    counters = result.report.counters
    assert counters["vehicle exclusions"] >= 2, counters
    # (Readmissions are checked on the plans above: the ground's counter of them is not.)
    assert counters["operator commands"] == 1 and counters["operator commands refused"] == 1


async def _fly(
    s: Scenario, keys: Keys, seen: MavlinkListener, mp: MavProxy, observer: ZenohBus
) -> None:
    """The operator's part (the module doc), on a running mission."""
    async with MissionWatch(observer, keys) as w:
        await w.until(lambda: len(w.plans) >= 5, WAIT_S, "five plans")
        await asyncio.to_thread(mp.wait_for, r"Detected vehicle 3:1", WAIT_S)

        # 1. MAVProxy takes vehicle 1: HOLD.
        await _mode_set(mp, TAKEN + 1, FlightMode.HOLD)
        await w.until(
            lambda: (t := w.last_telemetry(TAKEN)) is not None and t.override == "operator: HOLD",
            WAIT_S,
            "the bridge reporting the operator's HOLD",
        )
        t_taken, n_plans = w.t_s, len(w.plans)
        await w.until(
            lambda: any(h.vehicles.get(TAKEN) == "excluded: operator: HOLD" for h in w.health),
            WAIT_S,
            "health saying why",
        )
        await w.until(lambda: w.t_s >= t_taken + HOLD_S, WAIT_S, f"{HOLD_S} s of HOLD")
        # It stayed in HOLD, and still is: the service never switched it back. "From the
        # override on" in arrival order (one bridge's messages arrive in order): selected by
        # position stamp, a message from before the HOLD with an equal or later stamp came in
        # (CI saw it under load).
        reports = w.telemetry[TAKEN]
        first = next(i for i, t in enumerate(reports) if t.override == "operator: HOLD")
        held = reports[first:]
        assert held and all(t.mode == "hold" for t in held), {t.mode for t in held}
        assert seen.mode(TAKEN + 1) == "hold"
        # It held still once stopped (PX4's HOLD brakes to its stopping point first).
        still = np.array([t.position_xy_m for t in held if t.t_s >= t_taken + 5.0])
        assert len(still) >= 10 and float(np.max(np.linalg.norm(still - still[-1], axis=1))) < 2.0
        # The plans of that time leave it out; the others keep D_s from where it was when each
        # plan was made (its live position, from its telemetry).
        during = [p for _, p in w.plans[n_plans + 1 :]]
        assert len(during) >= 5, len(during)
        for plan in during:
            assert _excluded(plan, TAKEN), plan.slot
            assert abs(float(plan.plan.bandwidth_share.sum()) - 1.0) < 1e-6
            seen_at = [t for t in w.telemetry[TAKEN] if t.t_s <= plan.t_s] or w.telemetry[TAKEN]
            here = seen_at[-1].position_xy_m
            for m in range(s.M):
                if m != TAKEN:
                    assert _planned(plan, m), (plan.slot, m)
                    gap = float(np.linalg.norm(plan.plan.uav_xy_m[m] - here))
                    assert gap >= s.d_safe, (plan.slot, m, gap)

        # 2. MAVProxy gives it back: a plain switch to OFFBOARD.
        await _mode_set(mp, TAKEN + 1, FlightMode.OFFBOARD)
        n_back = len(w.plans)
        await w.until(
            lambda: any(_planned(p, TAKEN) for _, p in w.plans[n_back:]),
            WAIT_S,
            "vehicle 1 planned again after MAVProxy's OFFBOARD",
        )
        last = w.last_telemetry(TAKEN)
        assert last is not None and last.override == "" and last.mode == "offboard"

        # 3. Taken again; this time `release` on control gives it back.
        await _mode_set(mp, TAKEN + 1, FlightMode.HOLD)
        await w.until(
            lambda: (t := w.last_telemetry(TAKEN)) is not None and t.override != "",
            WAIT_S,
            "the second HOLD noticed",
        )
        reply = await w.request("release-1", "release", TAKEN)
        assert reply.accepted, reply
        assert reply.vehicles == (TAKEN,) and "released" in reply.effect
        n_rel = len(w.plans)
        await w.until(
            lambda: any(_planned(p, TAKEN) for _, p in w.plans[n_rel:]),
            WAIT_S,
            "vehicle 1 planned again after release",
        )
        await asyncio.to_thread(seen.wait_for_mode, TAKEN + 1, "offboard", 60.0)
        # Released while flown by the service: refused, nothing done.
        again = await w.request("release-2", "release", TAKEN)
        assert not again.accepted and "flown by the service" in again.reason
