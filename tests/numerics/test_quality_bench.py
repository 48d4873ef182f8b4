"""bench/quality.py cannot rot: its own statement of the slot problem agrees with the planner's
SlotConstraints, its misses count as misses, and it runs end to end at a tiny size."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

from isac_mission.config import Scenario
from isac_mission.experiment.closed_loop import draw_run_noise, record_slot_inputs
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import SlotInput, plan_slot
from isac_mission.tracking.pcrb import PlanningObjective, SensingParams
from isac_mission.types import SlotPlan, SolveReport

BENCH = Path(__file__).resolve().parents[2] / "bench" / "quality.py"


@pytest.fixture(scope="module")
def qb() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_quality", BENCH)
    assert spec is not None and spec.loader is not None
    module = sys.modules.setdefault("bench_quality", importlib.util.module_from_spec(spec))
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def recorded(paper: Scenario, qb: ModuleType) -> tuple[Scenario, SolverKit, list[SlotInput]]:
    s = qb.paper_problem(paper.with_changes(N=12))
    kit = SolverKit(s)
    return s, kit, record_slot_inputs(s, "proposed", draw_run_noise(s, 7), kit)[1]


def _variants(s: Scenario, inp: SlotInput, rng: np.random.Generator) -> list[SlotInput]:
    """The slot as recorded; with velocities and UAV 0 at the area's west edge heading out (so
    the coasting point is clipped to the 14h disk and to the area); with keep-out points 45 m
    from two UAVs."""
    velocity = rng.normal(0, 10, size=(s.M, 2))
    velocity[0] = [-400.0, 5.0]
    prev = inp.prev_xy_m.copy()
    prev[0, 0] = 10.0
    phi = rng.uniform(0, 2 * np.pi, 2)
    keep_out = inp.prev_xy_m[:2] + 45.0 * np.column_stack([np.cos(phi), np.sin(phi)])
    return [
        inp,
        dataclasses.replace(inp, prev_xy_m=prev, prev_velocity_mps=velocity),
        dataclasses.replace(inp, keep_out_xy_m=keep_out),
    ]


def test_own_check_agrees_with_slot_constraints(
    qb: ModuleType, recorded: tuple[Scenario, SolverKit, list[SlotInput]]
) -> None:
    s0, kit, inputs = recorded
    rng = np.random.default_rng(3)
    limited = s0.with_changes(planner=s0.planner.model_copy(update={"accel_limit_mps2": 40.0}))
    n_true = n_false = 0
    for inp in inputs[1::3]:
        plan = plan_slot(inp, kit, "proposed")
        for k, variant in enumerate(_variants(s0, inp, rng)):
            s = limited if k == 1 else s0
            p = qb.exact_problem(s, variant, plan)
            if k == 1:  # clipped to the 14h disk, then into the area
                assert p.ballistic_xy is not None and p.ballistic_xy[0, 0] == 0.0
            else:
                assert p.ballistic_xy is None
            cons = qb.planner_constraints(p)
            step = s.v_max * s.dt
            starts = [qb.random_start(p, rng) for _ in range(5)]
            for start in starts:  # random_start's points are feasible by the own check
                assert start is not None
                assert bool(cons.feasible(start[0][None], start[1][None])[0])
            for _ in range(200):
                base = starts[rng.integers(len(starts))]
                assert base is not None
                Q = base[0] + rng.normal(0, rng.choice([0.3, 3.0, 0.5 * step]), size=(s.M, 2))
                eta = rng.dirichlet(np.ones(s.M)) if rng.uniform() < 0.3 else base[1]
                mine = qb.own_check(p, Q, eta)
                assert mine == bool(cons.feasible(Q[None], eta[None])[0])
                n_true += mine
                n_false += not mine
    assert n_true > 50 and n_false > 50  # both sides of the boundary were tried


def test_slsqp_answers_are_feasible_and_a_failed_plan_is_a_miss(
    qb: ModuleType, recorded: tuple[Scenario, SolverKit, list[SlotInput]]
) -> None:
    s, kit, inputs = recorded
    inp = inputs[5]
    plan = plan_slot(inp, kit, "proposed")
    p = qb.exact_problem(s, inp, plan)
    objective = PlanningObjective(
        inp.lead.prior_information, inp.lead.state_pred, SensingParams.from_scenario(s)
    )
    start = qb.random_start(p, np.random.default_rng(1))
    assert start is not None
    answer, _ = qb.slsqp(p, objective, *start)
    assert answer is not None
    assert qb.own_check(p, *answer)
    assert objective.value(*answer) <= objective.value(*start) * (1 + 1e-9)
    ref = qb.Reference(best=plan.pcrb_trace, n_feasible=1, n_reach=1, n_capped=0)
    failed = dataclasses.replace(plan, report=SolveReport("infeasible", "test"))
    assert isinstance(failed, SlotPlan)
    none = qb.Reference(best=math.inf, n_feasible=0, n_reach=0, n_capped=0)
    r = qb.ratios([plan, failed, plan], [ref, ref, none])
    assert r[0] == pytest.approx(1.0)
    assert np.isinf(r[1]) and np.isinf(r[2])


def test_runs_end_to_end_at_a_tiny_size(qb: ModuleType, capsys: pytest.CaptureFixture[str]) -> None:
    common = ["--slots", "2", "--seeds", "2", "--starts", "2", "--repeats", "1", "--workers", "1"]
    summary = qb.main(["--m", "3", "6", "--run-slots", "4", *common])
    out = capsys.readouterr().out
    assert len(summary) == 2
    assert "plan / best" in out and "default proposed" in out and "time per slot" in out
    for headline in summary.values():
        assert 0.0 <= headline["within1"] <= 1.0
