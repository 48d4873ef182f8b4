"""The notebook-sized entry points behind `import isac_mission as im`.

Each function is a thin composition of the library's own pieces (`config`, `planning.slot`,
`experiment.closed_loop`, `records`): load a scenario, build its solver kit, plan one slot, fly
one closed loop and get its trace back in memory, the same records a trace file holds
(docs/trace.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.experiment.closed_loop import RunResult, SlotOutcome, draw_run_noise
from isac_mission.experiment.closed_loop import run_closed_loop as _fly
from isac_mission.experiment.montecarlo import outcome_record
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method, SlotInput, warm_up
from isac_mission.planning.slot import plan_slot as _plan
from isac_mission.records import SlotRecord, Trace
from isac_mission.tracking.cycle import CycleModel, TrackState, predict
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.priorities import scripted_priorities
from isac_mission.types import Gaussian, SlotPlan


def build_kit(scenario: Scenario) -> SolverKit:
    """The scenario's convex problems, built once (DPP) and warmed up; pass it to `plan_slot`
    and `run_closed_loop` to re-solve without rebuilding."""
    kit = SolverKit(scenario)
    warm_up(kit)
    return kit


def first_slot_input(scenario: Scenario) -> SlotInput:
    """What the planner knows at slot 1 with a perfect start: the UAVs at their start points
    (uav_start_xy, m), equal shares 1/M, no association yet, at rest, and the target's prior
    (x0, P0) predicted one slot by the slot recursion's `predict` (tracking/cycle.py: the
    EKF prediction, and the planner's prior chosen by tracker.bound_prior)."""
    start = TrackState(
        belief=Gaussian(x=scenario.x0.copy(), P=scenario.P0.copy()),
        bound=Bound.from_covariance(scenario.P0.copy()),
    )
    slot_1 = predict(CycleModel.from_scenario(scenario), start)
    return SlotInput(
        prev_xy_m=scenario.uav_start_xy.copy(),
        prev_bandwidth_share=np.full(scenario.M, 1.0 / scenario.M),
        prev_bs_of_uav=None,
        targets=(slot_1.belief(scenario.motion),),
        prev_velocity_mps=np.zeros((scenario.M, 2)),
    )


def plan_slot(
    scenario: Scenario,
    slot_input: SlotInput | None = None,
    *,
    method: Method = "proposed",
    kit: SolverKit | None = None,
) -> SlotPlan:
    """Plan one slot: next waypoints uav_xy_m [M, 2] (m), BS per UAV, bandwidth shares [M] and
    the planned tr(PCRB). Without `slot_input`, slot 1 from `first_slot_input`; without `kit`,
    one is built (`build_kit`). An infeasible slot comes back with report.status
    "infeasible" and the fallback plan, not an exception."""
    inp = first_slot_input(scenario) if slot_input is None else slot_input
    return _plan(inp, build_kit(scenario) if kit is None else kit, method)


@dataclass(frozen=True)
class ClosedLoopRun:
    """One closed-loop mission: the per-slot arrays (`result`: est, true [N, 4], pcrb
    [N, 4, 4], uav_xy [N, M, 2], ...) and its trace (`trace`: the config and the slot records
    a trace file of this run holds; plot it with `plot_trajectories(run.trace, ax=ax)`)."""

    result: RunResult
    trace: Trace


def run_closed_loop(
    scenario: Scenario,
    seed: int | None = None,
    *,
    method: Method = "proposed",
    kit: SolverKit | None = None,
) -> ClosedLoopRun:
    """Fly one offline mission of N slots (Section II-C) with `method`; the noise of the run
    comes from `seed` (default: the scenario's), exactly as run `r` of `simulate` with base
    seed `seed - r`."""
    run_seed = scenario.seed if seed is None else seed
    records: list[SlotRecord] = []

    def keep(outcome: SlotOutcome) -> None:
        records.append(
            outcome_record(outcome, scripted_priorities(scenario.priority_changes, outcome.slot))
        )

    result = _fly(
        scenario,
        method,
        draw_run_noise(scenario, run_seed),
        build_kit(scenario) if kit is None else kit,
        keep,
    )
    config = scenario.trace_config() | {"seed": run_seed, "method": method}
    return ClosedLoopRun(result=result, trace=Trace(config=config, slots=records))
