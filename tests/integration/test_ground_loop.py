"""The ground loop against the simulated world over real Zenoh on loopback (no MAVLink bridge:
the vehicles stay where they are, and the loop plans from the positions in the detections)."""

from __future__ import annotations

import asyncio
import dataclasses
from pathlib import Path

import numpy as np

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.planning.fleet import Planner
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method, SlotInput, plan_slot
from isac_mission.records import read_trace
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.tracking.cycle import TrackState
from isac_mission.types import SlotPlan
from isac_mission.wire import HealthMsg, Keys, PlanMsg, TrackMsg, decode
from sim.world import run_world
from sim.world_options import WorldOptions
from tests.support.independent.pcrb import compare_pcrb
from tests.support.ports import sitl_ports


async def _mission(
    s: Scenario,
    port: int,
    trace: Path,
    *,
    slots: int,
    resume: bool = False,
    planner: Planner = plan_slot,
) -> tuple[list[bytes], list[bytes], list[bytes], int]:
    s = dataclasses.replace(s, N=slots)
    endpoint = tcp_loopback(port)
    keys = Keys(s.mission_id)
    plans: list[bytes] = []
    tracks: list[bytes] = []
    health: list[bytes] = []
    with ZenohBus.open(BusSettings.hub(endpoint)) as bus:
        settings = GroundSettings(trace_path=trace, resume=resume, planner=planner)
        loop = GroundLoop(s, bus, settings)

        async def collect(key: str, into: list[bytes]) -> None:
            async with bus.subscribe(key) as sub:
                async for _k, payload in sub:
                    into.append(payload)

        stop_world = asyncio.Event()
        stop_ground = asyncio.Event()
        opts = WorldOptions(
            speed=50.0,
            lockstep=True,
            lockstep_timeout_s=20.0,
            bus=BusSettings(connect=(endpoint,)),
            **sitl_ports(3).world_kwargs(),  # free ports, not PX4's own
            seed=3,
        )
        async with asyncio.TaskGroup() as tg:
            collectors = [
                tg.create_task(collect(keys.plan, plans)),
                tg.create_task(collect(keys.track, tracks)),
                tg.create_task(collect(keys.health, health)),
            ]
            world = tg.create_task(run_world(s, opts, stop_world))
            report = await asyncio.wait_for(loop.run(stop_ground), timeout=120)
            stop_world.set()
            await asyncio.wait_for(world, timeout=30)
            for c in collectors:
                c.cancel()
    return plans, tracks, health, report.counters["slots"]


async def test_ground_loop_flies_every_slot_and_traces_it(
    paper: Scenario, free_tcp_port: int, tmp_path: Path
) -> None:
    trace_path = tmp_path / "live.jsonl"
    plans, tracks, health, slots = await _mission(paper, free_tcp_port, trace_path, slots=8)
    assert slots == 8
    plan_slots = [decode(PlanMsg, p).slot for p in plans]
    assert plan_slots == list(range(1, 9))
    assert [decode(TrackMsg, t).slot for t in tracks] == list(range(1, 9))
    assert decode(HealthMsg, health[-1]).status in ("running", "done")
    trace = read_trace(trace_path)
    assert [r.slot for r in trace.slots] == list(range(1, 9))
    assert all(r.target_true is not None for r in trace.slots)
    assert compare_pcrb(trace) == []
    # Measurements were taken where the vehicles are: the start points (nobody flies them).
    np.testing.assert_allclose(trace.slots[-1].uav_xy_m, paper.uav_start_xy, atol=0.5)
    err = np.linalg.norm(trace.slots[-1].target_est[:2] - trace.slots[-1].target_true[:2])
    assert err < 5 * np.sqrt(np.trace(np.asarray(trace.slots[-1].P)[:2, :2]))


async def test_restarted_ground_loop_resumes_from_the_last_traced_slot(
    paper: Scenario, free_tcp_port: int, tmp_path: Path
) -> None:
    trace_path = tmp_path / "live.jsonl"
    await _mission(paper, free_tcp_port, trace_path, slots=4)
    first = read_trace(trace_path)
    assert [r.slot for r in first.slots] == [1, 2, 3, 4]
    # A new loop on the same trace continues after slot 4 with the traced P and J.
    from isac_mission.service.ground.tracefile import RecordOutput

    settings = GroundSettings(method="proposed", trace_path=trace_path, resume=True)
    resume = RecordOutput(paper, settings, GroundReport(), None).open()
    assert resume is not None and isinstance(resume.saved, TrackState)
    assert resume.slot == 4
    np.testing.assert_allclose(resume.saved.bound.J, first.slots[-1].J)
    np.testing.assert_allclose(resume.saved.belief.P, first.slots[-1].P)


async def test_ground_loop_gives_the_planner_the_predicted_covariance_and_last_plan(
    paper: Scenario, free_tcp_port: int, tmp_path: Path
) -> None:
    """Over the wire: slot n's planner input carries last slot's plan as published (the whole
    fleet is active) and the EKF's predicted covariance F P_{n-1} F^T + W, recomputed here from
    the traced P of slot n-1 (P0 before slot 1)."""
    inputs: list[SlotInput] = []

    def recording(inp: SlotInput, kit: SolverKit, method: Method) -> SlotPlan:
        inputs.append(inp)
        return plan_slot(inp, kit, method)

    trace_path = tmp_path / "live.jsonl"
    plans, _, _, slots = await _mission(
        paper, free_tcp_port, trace_path, slots=5, planner=recording
    )
    assert slots == 5
    published = {(p := decode(PlanMsg, b)).slot: p for b in plans}
    trace = read_trace(trace_path)
    F, W = transition_matrix(paper.dt), process_noise(paper.dt, paper.kappa)
    posteriors = [paper.P0, *(np.asarray(r.P) for r in trace.slots)]
    assert len(inputs) == 5  # plans 1..5 (none after the last slot)
    assert inputs[0].prev_plan is None
    for n, inp in enumerate(inputs, start=1):
        assert inp.lead.cov_pred is not None
        want = F @ posteriors[n - 1] @ F.T + W
        np.testing.assert_allclose(inp.lead.cov_pred, want, rtol=1e-9, atol=1e-12)
        if n > 1:
            prev = inp.prev_plan
            assert prev is not None
            sent = published[n - 1]
            np.testing.assert_allclose(prev.uav_xy_m, sent.plan.uav_xy_m, atol=1e-6)
            np.testing.assert_allclose(prev.bandwidth_share, sent.plan.bandwidth_share, atol=1e-9)
            np.testing.assert_array_equal(prev.bs_of_uav, sent.plan.bs_of_uav)
