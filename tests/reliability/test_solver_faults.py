"""Solver trouble (issue 7, item 4): a solver error, a time-out past the per-slot budget, and an
infeasible stretch after an operator raises R_th mid-run; each slot falls back and says why, and
the next slot plans normally.

Real parts: the simulated world (target, sensing, clock) and the ground loop over real Zenoh on
loopback, real cvxpy/Clarabel planning. The injected faults wrap the real planner: on given
slots it raises cvxpy's SolverError, or blocks past the budget before planning.
"""

from __future__ import annotations

import asyncio
import dataclasses
import threading
from pathlib import Path

import cvxpy as cp
import numpy as np

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method, SlotInput, plan_slot
from isac_mission.records import read_trace
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.types import SlotPlan
from isac_mission.wire import ControlMsg, Keys, PlanMsg, decode, encode
from sim.world import run_world
from sim.world_options import WorldOptions
from tests.support.ports import sitl_ports

ERROR_SLOT, SLOW_SLOT = 3, 5
BUDGET_S = 0.4


class FaultyPlanner:
    """plan_slot, except: the ERROR_SLOT-th call raises SolverError, the SLOW_SLOT-th call blocks
    until released (long after the budget), then plans."""

    def __init__(self) -> None:
        self.calls = 0
        self.release = threading.Event()

    def __call__(self, inp: SlotInput, kit: SolverKit, method: Method) -> SlotPlan:
        self.calls += 1
        if self.calls == ERROR_SLOT:
            raise cp.error.SolverError("injected: CLARABEL failed")
        if self.calls == SLOW_SLOT:
            self.release.wait(timeout=60.0)
        return plan_slot(inp, kit, method)


async def test_solver_error_timeout_and_infeasible_slots_fall_back_and_recover(
    paper: Scenario, free_tcp_port: int, tmp_path: Path
) -> None:
    s = dataclasses.replace(paper, N=16)
    endpoint = tcp_loopback(free_tcp_port)
    keys = Keys(s.mission_id)
    faulty = FaultyPlanner()
    trace_path = tmp_path / "faults.jsonl"
    plans: list[SlotPlan] = []
    infeasible_seen = asyncio.Event()
    with ZenohBus.open(BusSettings.hub(endpoint)) as bus:
        loop = GroundLoop(
            s, bus, GroundSettings(trace_path=trace_path, plan_budget_s=BUDGET_S, planner=faulty)
        )

        async def operator() -> None:
            """Raise R_th to 5 Gbit/s after plan 8, restore 10 Mbit/s after the first
            infeasible plan; release the blocked planner thread once its slot has passed."""
            raised = restored = False
            async with bus.subscribe(keys.plan) as sub:
                async for _k, payload in sub:
                    msg = decode(PlanMsg, payload)
                    plans.append(msg.plan)
                    if msg.slot == SLOW_SLOT + 1:
                        faulty.release.set()
                    if msg.slot == 8 and not raised:
                        raised = True
                        bus.publish(
                            keys.control,
                            encode(ControlMsg.set_params(8, 0.0, "raise", rate_min_mbps=5000.0)),
                        )
                    if raised and not restored and msg.plan.report.status == "infeasible":
                        restored = True
                        infeasible_seen.set()
                        bus.publish(
                            keys.control,
                            encode(
                                ControlMsg.set_params(msg.slot, 0.0, "restore", rate_min_mbps=10.0)
                            ),
                        )

        opts = WorldOptions(
            speed=20.0,
            lockstep=True,
            lockstep_timeout_s=20.0,
            bus=BusSettings(connect=(endpoint,)),
            **sitl_ports(3).world_kwargs(),  # free ports, not PX4's own
            seed=5,
        )
        stop_world = asyncio.Event()
        async with asyncio.TaskGroup() as tg:
            op = tg.create_task(operator())
            world = tg.create_task(run_world(s, opts, stop_world))
            report = await asyncio.wait_for(loop.run(asyncio.Event()), timeout=180)
            stop_world.set()
            await asyncio.wait_for(world, timeout=30)
            op.cancel()
    faulty.release.set()

    assert report.counters["slots"] == s.N
    assert report.counters["planner errors"] == 1
    assert report.counters["plans timed out"] == 1
    assert report.counters["operator commands"] == 2
    assert infeasible_seen.is_set()
    trace = read_trace(trace_path)
    status = {r.slot: r.status for r in trace.slots}
    by_slot = {r.slot: r for r in trace.slots}
    # The error: the communication-optimal fallback, with the reason; the next slot is normal.
    assert status[ERROR_SLOT] == "solver error"
    assert "SolverError" in (by_slot[ERROR_SLOT].reason or "")
    assert "communication-optimal" in (by_slot[ERROR_SLOT].reason or "")
    assert status[ERROR_SLOT + 1] == "ok"
    # The time-out: hold (waypoints = where the UAVs were), the next slot normal again.
    assert status[SLOW_SLOT] == "timeout"
    assert "budget" in (by_slot[SLOW_SLOT].reason or "")
    hold = by_slot[SLOW_SLOT]
    np.testing.assert_allclose(hold.plan_xy, by_slot[SLOW_SLOT - 1].uav_xy_m, atol=1e-6)
    assert status[SLOW_SLOT + 1] == "ok"
    # R_th raised: infeasible slots that say why; after the restore, ok again to the end.
    infeasible = [n for n, st in status.items() if st == "infeasible"]
    assert infeasible and min(infeasible) >= 9
    assert all("R_th" in (by_slot[n].reason or "") for n in infeasible)
    assert status[s.N] == "ok"
    assert all(status[n] == "ok" for n in range(max(infeasible) + 1, s.N + 1))
    # Every other slot planned normally.
    faulted = {ERROR_SLOT, SLOW_SLOT, *infeasible}
    assert all(st == "ok" for n, st in status.items() if n not in faulted), status
