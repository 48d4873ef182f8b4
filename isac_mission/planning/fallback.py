"""The fallback policy: what a slot flies when a method cannot plan, and the reason it says.

Every plan's report names its fallback (SolveReport.fallback, the trace's `fallback`; the
summaries count them), from most to least planned:

| fallback | when | what flies | where |
|---|---|---|---|
| "" | the method planned | its plan | the method |
| `horizon: <why>` | the horizon's answer is not kept (IPOPT failed, or stopped at its cap on an iterate infeasible or no better than its start; the answer breaks the exact check or the leg limits) | the per-slot plan (`per_slot_instead`; its best effort where it is infeasible: the horizon still starts from it) | planning/horizon.py |
| `infeasible` | no plan meets 14a-14j (the link cannot reach R_th, or the search ends infeasible) | `best_effort`: the link-optimal waypoints (or the coasting point), away from the target first; with the vehicle model, threatened UAVs on evasive legs | planning/per_slot.py, planning/benchmarks.py |
| `evasive` | with the vehicle model, the plan's end state leaves UAVs that cannot brake apart before D_s or dodge the target | `kept_viable`: those UAVs on evasive legs (planning/evasion.py), the others the plan | planning/slot.py |
| `solver error` | the planner raised | the communication-optimal plan, else `hold_plan` | planning/fleet.py |
| `timeout`, `no vehicles` | the live budget passed; nothing can follow a plan | `hold_plan`: every vehicle holds where it is | service/ground/loop.py, planning/fleet.py |
| `late` | a plan is published after its slot's end | that plan, marked | service/ground/loop.py |

An operator's hold of every vehicle is no fallback: its slots have status `operator hold`
(`OPERATOR_HOLD`), the hold plan, and no `fallback` (planning/fleet.py).

Pure: no clock, no RNG, no I/O.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.radar import SensingParams
from isac_mission.planning.association import association_costs, optimal_assignment
from isac_mission.planning.evasion import (
    Parties,
    coasting_threats,
    evasive_legs,
    target_escape,
    unviable_pairs,
)
from isac_mission.planning.feasibility import operating_area
from isac_mission.planning.margins import SafetyMargins, manoeuvre_margin_m
from isac_mission.planning.problem import (
    SlotInput,
    SlotProblem,
    slot_clearance_m,
    targets_objective,
)
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.types import BoolArray, FloatArray, IntArray, SlotPlan, SolveReport

OPERATOR_HOLD = "operator hold"
"""Status of a slot in which an operator's `hold` or `land` holds every vehicle: the hold plan,
flown on the operator's word (no fallback, no error)."""

NO_BS = -1
"""bs_of_uav of a vehicle outside the plan."""


def evade_target(
    planned_xy: FloatArray, prev_xy: FloatArray, target_xy: FloatArray, d_safe: float, step: float
) -> FloatArray:
    """Best-effort waypoints [M, 2]: a UAV whose planned waypoint is closer than D_s to the
    predicted target moves straight away from it by `step` instead (14j before communication)."""
    out = np.array(planned_xy, dtype=float)
    for m in np.flatnonzero(np.linalg.norm(out - target_xy, axis=1) < d_safe):
        away = prev_xy[m] - target_xy
        norm = float(np.linalg.norm(away))
        direction = away / norm if norm > 1e-9 else np.array([1.0, 0.0])
        out[m] = prev_xy[m] + direction * step * (1 - 1e-12)
    return out


def kept_apart(planned_xy: FloatArray, prev_xy: FloatArray, separation_m: float) -> FloatArray:
    """Best-effort waypoints [M, 2] no closer than separation_m to each other where the UAVs'
    previous waypoints prev_xy [M, 2] were: a UAV whose planned waypoint comes within
    separation_m of another UAV's holds at its previous one instead (14i before communication:
    two UAVs served by one BS share its link-optimal point), until no moved UAV is too close."""
    out = np.array(planned_xy, dtype=float)
    prev = np.asarray(prev_xy, dtype=float)
    for _ in range(len(out)):
        gap = np.linalg.norm(out[:, None] - out[None], axis=-1)
        np.fill_diagonal(gap, np.inf)
        close = np.any(gap < separation_m, axis=1)
        moved = close & np.any(out != prev, axis=1)
        if not moved.any():
            break
        out[moved] = prev[moved]
    return out


def best_effort(problem: SlotProblem, reason: str) -> SlotPlan:
    """The plan of a slot no method can solve (status and fallback "infeasible"): the
    link-optimal waypoints (a UAV that would come within D_s of another holds instead), or where
    the vehicles coast to when the planner respects their dynamics; either way away from the
    target first, inside the operating area. With the
    vehicle model a UAV that coasts toward another UAV, the target or a keep-out point, or that
    could no longer dodge the target, flies its evasive leg instead (planning/evasion.py), its
    end velocity in the plan."""
    cons = problem.constraints
    comm = problem.communication
    best = comm.uav_xy if problem.ballistic_xy_m is None else problem.ballistic_xy_m
    inp = problem.inp
    s = problem.scenario
    report = SolveReport("infeasible", reason, solve_s=problem.elapsed_s(), fallback="infeasible")
    if s.planner.vehicle_model and inp.prev_velocity_mps is not None:
        parties = slot_parties(inp, s)
        threat, _ = coasting_threats(parties, s.a_max, s.dt)
        start_viable, dodge = _target_escape(parties, s, inp.prev_xy_m, inp.prev_velocity_mps)
        threat[:, s.M] |= ~start_viable
        xy, velocity, _ = evasive_legs(
            parties, threat, best, (best - inp.prev_xy_m) / s.dt, s.a_max, s.v_max, s.dt, dodge
        )
        plan = problem.plan(np.clip(xy, *cons.area_bounds()), comm.eta, report)
        return replace(plan, uav_velocity_mps=velocity)
    apart = kept_apart(best, inp.prev_xy_m, SafetyMargins.of(s).separation_m)
    xy = evade_target(
        apart, inp.prev_xy_m, inp.lead.state_pred[:2], cons.clearance_m, problem.max_step_m
    )
    xy = np.clip(xy, *cons.area_bounds())  # the vehicles' geofence would clamp it anyway
    return problem.plan(xy, comm.eta, report)


def slot_parties(inp: SlotInput, s: Scenario) -> Parties:
    """The slot's parties (planning/evasion.py) at its start: the UAVs at prev_velocity_mps
    (D_s plus the margins apart), the lead target a slot before its prediction at its
    predicted velocity (the slot's 14j clearance), the keep-out points."""
    assert inp.prev_velocity_mps is not None
    lead = inp.lead
    return Parties.of(
        inp.prev_xy_m,
        inp.prev_velocity_mps,
        SafetyMargins.of(s).separation_m,
        np.asarray(lead.position_at(-s.dt), dtype=float),
        np.asarray(lead.state_pred[2:4], dtype=float),
        slot_clearance_m(inp, s),
        inp.keep_out_xy_m,
    )


def kept_viable(plan: SlotPlan, inp: SlotInput, s: Scenario, sensing: SensingParams) -> SlotPlan:
    """`plan`, or under the vehicle model, where its end state leaves UAVs that cannot brake
    apart before D_s (evasion.unviable_pairs) or dodge the target (evasion.target_escape), the
    plan with those UAVs on their evasive legs (fallback "evasive"; the bound re-evaluated, the
    association and shares kept)."""
    if not s.planner.vehicle_model or inp.prev_velocity_mps is None:
        return plan
    if plan.uav_velocity_mps is None:
        return plan
    parties = slot_parties(inp, s)
    unviable = _unviable(parties, s, plan.uav_xy_m, plan.uav_velocity_mps)
    if not unviable.any():
        return plan
    _, dodge = _target_escape(parties, s, inp.prev_xy_m, inp.prev_velocity_mps)
    threat = unviable
    for _ in range(s.M):  # an evading UAV can leave a neighbour unviable: it evades too
        xy, velocity, evading = evasive_legs(
            parties, threat, plan.uav_xy_m, plan.uav_velocity_mps, s.a_max, s.v_max, s.dt, dodge
        )
        more = threat | _unviable(parties, s, xy, velocity)
        if (more == threat).all():
            break
        threat = more
    xy = np.clip(xy, *operating_area(s))
    objective = targets_objective(inp.targets, sensing)
    uavs = ", ".join(str(m) for m in np.flatnonzero(evading))
    dodging = threat[evading, s.M].any()
    why = f"evasive legs for UAVs {uavs}: their planned end states could not " + (
        "brake apart before D_s or dodge the target" if dodging else "brake apart before D_s"
    )
    report = replace(
        plan.report,
        reason=why + (f"; {plan.report.reason}" * bool(plan.report.reason)),
        fallback=plan.report.fallback or "evasive",
    )
    return replace(
        plan,
        uav_xy_m=xy,
        uav_velocity_mps=velocity,
        pcrb_trace=float(objective.value(xy, plan.bandwidth_share)),
        report=report,
    )


def _target_escape(
    parties: Parties, s: Scenario, xy_m: FloatArray, velocity_mps: FloatArray, end: bool = False
) -> tuple[BoolArray, FloatArray]:
    """evasion.target_escape of UAVs at xy_m [M, 2] moving at velocity_mps [M, 2] from the
    slot's target (its party: at the slot's start; end: at its predicted end state), which may
    manoeuvre at a_T: the distance to keep is the slot's 14j clearance without its manoeuvre
    margin, which target_escape's reach a_T (t + known)^2 / 2 replaces."""
    M = s.M
    target_xy = parties.xy_m[M] + s.dt * parties.velocity_mps[M] * end
    return target_escape(
        xy_m,
        velocity_mps,
        target_xy,
        parties.velocity_mps[M],
        float(parties.clearance_m[M]) - manoeuvre_margin_m(s),
        s.a_max,
        s.a_target,
        s.v_max,
        s.dt,
        known_s=s.dt * end,
    )


def _unviable(
    parties: Parties, s: Scenario, end_xy_m: FloatArray, end_velocity_mps: FloatArray
) -> BoolArray:
    """[M, P] evasion.unviable_pairs of the end state end_xy_m [M, 2], end_velocity_mps [M, 2],
    with the target's column: the UAVs that could not dodge the target from there."""
    unviable = unviable_pairs(parties, end_xy_m, end_velocity_mps, s.a_max)
    viable, _ = _target_escape(parties, s, end_xy_m, end_velocity_mps, end=True)
    unviable[:, s.M] = ~viable
    return unviable


def per_slot_instead(base: SlotPlan, method: str, why: str, kind: str, solve_s: float) -> SlotPlan:
    """`base` (a per-slot plan, already feasible or already the best effort) flown instead of
    `method`'s answer, saying why; kind: the short fallback kind the summaries count."""
    report = replace(
        base.report,
        reason=f"{method}: {why}; per-slot plan"
        + (f"; {base.report.reason}" * bool(base.report.reason)),
        solve_s=solve_s,
        fallback=base.report.fallback or f"{method}: {kind}",
    )
    return replace(base, report=report)


def hold_plan(
    s: Scenario,
    sensing: SensingParams,
    uav_xy_m: FloatArray,
    prev_bandwidth_share: FloatArray,
    prev_bs_of_uav: IntArray | None,
    excluded: tuple[int, ...],
    targets: tuple[TargetBelief, ...],
    reason: str,
    status: str,
    solve_s: float = 0.0,
) -> SlotPlan:
    """Every vehicle holds where it is (uav_xy_m [M, 2]), with last slot's shares and association
    (a plan that needs no solver; its bound, the methods' objective over `targets`, is
    evaluated for the record). Without a last
    association (a hold at the first slot) each vehicle gets the communication-optimal BS for
    where it is (the exact assignment, no LP). A vehicle outside the plan (`excluded`) gets no
    BS and share 0, as in every widened plan; when every vehicle is outside it, nobody is
    served: every share is 0 (the plan message's one case of shares that do not sum to 1)."""
    M = s.M
    out = list(excluded)
    eta = np.array(prev_bandwidth_share, dtype=float)
    eta[out] = 0.0
    if eta.sum() > 0:
        eta = eta / eta.sum()
    elif len(out) < M:
        eta = np.full(M, 1.0 / (M - len(out)))
        eta[out] = 0.0
    if prev_bs_of_uav is not None:
        assoc = np.array(prev_bs_of_uav, dtype=np.int64)
    else:
        costs = association_costs(uav_xy_m, s.bs_xy, dH=s.dH, rho0=s.rho0, B=s.B)
        assoc = optimal_assignment(costs, s.n_a)
    assoc[out] = NO_BS
    pcrb = float("nan")  # no confirmed track: nothing to judge the hold by
    if targets:
        objective = targets_objective(targets, sensing)
        with np.errstate(divide="ignore"):
            pcrb = float(objective.value(uav_xy_m, np.maximum(eta, 1e-12)))
    return SlotPlan(
        np.array(uav_xy_m, dtype=float),
        assoc,
        eta,
        pcrb,
        SolveReport(
            status, reason, solve_s=solve_s, fallback="" if status == OPERATOR_HOLD else status
        ),
    )
