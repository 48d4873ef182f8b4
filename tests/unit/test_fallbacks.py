"""Every slot says why a method's answer was not flown (SolveReport.fallback, the trace's
`fallback`), and the summaries count them (docs/trace.md, "Fallbacks")."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.experiment.montecarlo import run_monte_carlo, summarize, trace_path
from isac_mission.experiment.trace_figures import trace_figures
from isac_mission.planning.fleet import KitCache, PlanningJob
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.records import SlotRecord, read_trace
from isac_mission.service.ground.report import MissionTotals
from isac_mission.tracking.beliefs import TargetBelief
from tests.support.ground_steps import predictions_of


def unreachable_rate(s: Scenario) -> Scenario:
    """R_th far above what any UAV position gives: every slot is infeasible."""
    return dataclasses.replace(s, r_th=1e12)


def test_infeasible_slots_are_traced_and_counted(paper: Scenario, tmp_path: Path) -> None:
    s = unreachable_rate(dataclasses.replace(paper, N=4))
    results = run_monte_carlo(s, ["proposed", "sd"], 1, seed=2, trace_dir=tmp_path)
    for method in ("proposed", "sd"):
        summary = summarize(results[method])
        assert summary.fallbacks == {"infeasible": 4}
        trace = read_trace(trace_path(tmp_path, method, 0))
        assert [r.fallback for r in trace.slots] == ["infeasible"] * 4
        assert trace_figures([trace])["fallbacks"].tolist() == [4.0]


def test_a_kept_answer_has_no_fallback(paper: Scenario, tmp_path: Path) -> None:
    s = dataclasses.replace(paper, N=3)
    results = run_monte_carlo(s, ["proposed"], 1, seed=2, trace_dir=tmp_path)
    assert summarize(results["proposed"]).fallbacks == {}
    trace = read_trace(trace_path(tmp_path, "proposed", 0))
    assert all(r.fallback is None for r in trace.slots)
    assert "fallback" not in trace.slots[0].to_dict()


def slot_input(s: Scenario) -> SlotInput:
    return SlotInput(
        prev_xy_m=s.uav_start_xy,
        prev_bandwidth_share=np.full(s.M, 1.0 / s.M),
        prev_bs_of_uav=None,
        targets=(TargetBelief(s.x0, np.asarray(np.linalg.inv(s.P0), dtype=float), s.motion, s.P0),),
        prev_velocity_mps=np.zeros((s.M, 2)),
    )


def test_the_horizon_names_its_fallback(paper: Scenario) -> None:
    horizon = paper.planner.horizon.model_copy(update={"max_iterations": 1})
    planner = paper.planner.model_copy(update={"vehicle_model": True, "horizon": horizon})
    s = dataclasses.replace(paper, planner=planner)
    plan = plan_slot(slot_input(s), SolverKit(s), "horizon")
    # From rest one iteration is already a better feasible horizon: flown, no fallback (the
    # cap's fallback is named in tests/numerics/test_horizon.py, on slots where it is not).
    assert plan.report.fallback == "" and plan.horizon is not None
    assert "Maximum_Iterations_Exceeded in 1 it, its last iterate kept" in plan.report.polish
    assert plan.report.status == "ok"
    # A horizon over an infeasible slot keeps the per-slot plan's own reason.
    bad = unreachable_rate(s)
    assert plan_slot(slot_input(bad), SolverKit(bad), "horizon").report.fallback == "infeasible"


def planning_job(s: Scenario) -> PlanningJob:
    """Slot 1's planning job from the start points, every vehicle planned."""
    return PlanningJob(
        slot=1,
        method="proposed",
        kits=KitCache(SolverKit(s)),
        uav_xy=s.uav_start_xy,
        uav_v=None,
        prev_eta=np.full(s.M, 1.0 / s.M),
        prev_assoc=None,
        predictions=predictions_of(
            (TargetBelief(s.x0, np.asarray(np.linalg.inv(s.P0), dtype=float), s.motion, s.P0),)
        ),
    )


def test_the_ground_loops_plans_name_theirs_and_the_totals_count_them(paper: Scenario) -> None:
    job = planning_job(paper)
    assert job.hold("timeout: ...", "timeout").report.fallback == "timeout"
    assert job.fallback_after_error("solver error: x", 0.1).plan.report.fallback == "solver error"
    totals = MissionTotals()
    for name in ("timeout", "timeout", "late", None):
        rec = read_like(paper, name)
        totals.add(rec)
    assert dict(totals.fallbacks) == {"timeout": 2, "late": 1}


def read_like(s: Scenario, fallback: str | None) -> SlotRecord:
    """A minimal slot record with the given fallback."""
    return SlotRecord(
        slot=1,
        method="proposed",
        status="ok",
        uav_xy_m=s.uav_start_xy,
        bandwidth_share=np.full(s.M, 1.0 / s.M),
        assoc=np.zeros(s.M, dtype=np.int64),
        target_true=None,
        target_est=s.x0,
        target_pred=s.x0,
        r_diag=np.ones(2 * s.M),
        pcrb_trace=1.0,
        solve_ms=1.0,
        P=s.P0,
        J=np.asarray(np.linalg.inv(s.P0), dtype=float),
        fallback=fallback,
    )


def test_a_plan_published_after_the_bridges_drop_it_is_marked_late(paper: Scenario) -> None:
    """The bridges drop a plan more than a slot after its slot's end (timebase.plan_is_late):
    the ground loop's record of that slot says so."""
    from isac_mission.service.ground.loop import GroundLoop
    from isac_mission.service.ground.settings import GroundSettings

    s = dataclasses.replace(paper, N=5)
    loop = GroundLoop(s, None, GroundSettings(), SolverKit(s))  # type: ignore[arg-type]  # no I/O here
    plan = plan_slot(slot_input(s), loop.kit)
    loop.mission_t0_s = 10.0
    loop.t_s = 10.0 + 3 * s.dt + 0.5  # slot 3 ended 0.5 s ago: still flown
    assert loop._marked_if_late(3, plan) is plan
    loop.t_s = 10.0 + 4 * s.dt + 0.5  # 1.5 slots after slot 3's end: dropped
    late = loop._marked_if_late(3, plan)
    assert late.report.fallback == "late"
    assert late.report.reason.startswith("late: published at 14.5 s, its slot ended at 13.0 s")
    assert loop.report.counters["plans late"] == 1
    np.testing.assert_array_equal(late.uav_xy_m, plan.uav_xy_m)


def test_an_operator_hold_of_every_vehicle_is_a_hold_not_a_failure(paper: Scenario) -> None:
    """Every vehicle held by an operator: status `operator hold`, no fallback, and nobody
    served (share 0, no BS), as the operator's reply says; the plan message carries it. A
    vehicle out for another reason (a lost link) makes it `no vehicles`, a fallback."""
    from isac_mission.wire import PlanMsg, decode, encode

    s = paper
    job = dataclasses.replace(
        planning_job(s),
        slot=4,
        prev_assoc=np.arange(s.M, dtype=np.int64) % s.K,
        excluded=tuple(range(s.M)),
        operator_held=tuple(range(s.M)),
    )
    plan = job.run()
    assert plan.report.status == "operator hold" and plan.report.fallback == ""
    np.testing.assert_array_equal(plan.bandwidth_share, np.zeros(s.M))
    np.testing.assert_array_equal(plan.bs_of_uav, np.full(s.M, -1))
    sent = decode(PlanMsg, encode(PlanMsg.from_plan(4, 10.0, plan)), n_uavs=s.M)
    np.testing.assert_array_equal(sent.plan.bandwidth_share, np.zeros(s.M))
    lost = dataclasses.replace(job, operator_held=tuple(range(s.M - 1))).run()
    assert lost.report.status == "no vehicles" and lost.report.fallback == "no vehicles"
    np.testing.assert_array_equal(lost.bandwidth_share, np.zeros(s.M))
    # Some vehicles held: the others share the bandwidth, the held ones have none.
    some = dataclasses.replace(job, excluded=(0,), operator_held=(0,)).hold("timeout", "timeout")
    assert some.bs_of_uav[0] == -1 and some.bandwidth_share[0] == 0.0
    assert some.bandwidth_share.sum() == pytest.approx(1.0)


def test_the_totals_count_each_status_by_name(paper: Scenario) -> None:
    """`run`'s summary takes its infeasible slots from the infeasible status alone: an
    operator's hold is counted as what it is."""
    totals = MissionTotals()
    for status in ("ok", "operator hold", "operator hold", "infeasible"):
        totals.add(dataclasses.replace(read_like(paper, None), status=status))
    assert totals.statuses == {"ok": 1, "operator hold": 2, "infeasible": 1}
