"""The paper's per-slot method: Algorithm 2 (alternating positions and shares), as printed and
polished.

- `proposed-sca`: Algorithm 2 alone, as printed: positions by Algorithm 1 (planning/positions.py)
  and shares by (P1.2.1) (planning/bandwidth.py), alternated until the relative decrease is at
  most epsilon;
- `proposed`: the same, with (planner.polish) the exact slot problem polished by IPOPT
  (planning/polish.py) after the first AO iteration (kept if it gains more than
  EARLY_POLISH_GAIN there, else Algorithm 2 resumes and is polished at its end), then from the
  best other leader of the band (`screen_leaders`).

`alternate` is the loop the benchmarks (planning/benchmarks.py) run too, with their options.

The leader screen: the slot problem has about one local optimum per UAV that takes most of the
band (0.75-0.9 of it: the information of a UAV grows as eta^2). Algorithm 2 starts from last
slot's shares and the polish from Algorithm 2's point, so both keep last slot's leader, while the
best plan may give the band to another UAV now as close to the target. The screen evaluates, at
the plan's waypoints, the objective with the shares of the leader and of UAV j swapped (one tr(C)
per UAV, no solve); a swap whose value is within SCREEN_RATIO of the plan's is a start for the
polish.

Pure: no clock but the plan's timer, no RNG, no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.planning.bandwidth import optimise_shares
from isac_mission.planning.communication import lemma1_shares
from isac_mission.planning.fallback import best_effort
from isac_mission.planning.feasibility import capacity_ok
from isac_mission.planning.polish import PolishNLP
from isac_mission.planning.positions import optimise_positions
from isac_mission.planning.problem import (
    PlansOnceToWarmUp,
    SlotInput,
    SlotProblem,
    build_slot_problem,
)
from isac_mission.tracking.pcrb import PlanningObjective
from isac_mission.types import FloatArray, SlotPlan, SolveReport

if TYPE_CHECKING:
    from isac_mission.planning.kit import SolverKit

EARLY_POLISH_GAIN = 1e-6
"""The early polish (after AO iteration 1) is kept only if it lowers tr(PCRB) by more than this
(relative) there: a smaller gain means Algorithm 2 had nearly converged, and its end point (which
the polish may then match only to IPOPT's tolerance) is polished instead."""

SCREEN_RATIO = 1.06
"""A swapped-leader start is polished when its tr(C) at the plan's waypoints is below
SCREEN_RATIO times the plan's tr(C)."""
MAX_STARTS = 1
"""At most this many swapped-leader starts are polished per slot (the best screened first)."""


@dataclass(frozen=True)
class Alternation:
    """What Algorithm 2 optimises: positions (False: the UAVs stay, SD), shares (False: equal
    shares 1/M, ABA), and whether the exact problem is polished (`proposed`)."""

    positions: bool = True
    shares: bool = True
    polish: bool = False


def polish_nlp(kit: SolverKit) -> PolishNLP:
    """The kit's exact slot problem (planning/polish.py), built on first use and kept."""
    s = kit.scenario
    return kit.built(
        "polish",
        lambda: PolishNLP(
            s, kit.n_keep_out, s.planner.polish_max_iterations, kit.solve_lock, kit.ipopt
        ),
    )


def alternate(problem: SlotProblem, kit: SolverKit, how: Alternation) -> SlotPlan:
    """Algorithm 2 on the slot problem (with the polish and the leader screen when how.polish);
    an infeasible slot returns the best effort (planning/fallback.py)."""
    s = problem.scenario
    cfg = s.planner
    inp = problem.inp
    cons = problem.constraints
    objective = problem.objective
    ballistic = problem.ballistic_xy_m
    moves = how.positions
    # Start where the vehicles can be: with a dynamics limit, where they coast to.
    Q = inp.prev_xy_m if ballistic is None or not moves else ballistic
    if not how.shares:
        eta = np.full(s.M, 1.0 / s.M)
    else:
        eta = inp.prev_bandwidth_share
        if bool(cons.rate_violations(Q[None], eta[None])[0]):
            eta = lemma1_shares(cons.full_rates(Q))
    f = objective.value(Q, eta)
    history = [f]
    n_pos = n_bw = n_ao = 0
    search = {"epsilon": cfg.epsilon, "step": cfg.line_search_step}
    note, reason, n_polish = "", "", 0
    # The polish's NLP is one target's problem: with several targets Algorithm 2 plans alone.
    single = objective if isinstance(objective, PlanningObjective) else None
    polish = how.polish and moves and single is not None
    polished_early, n_early = False, 0
    for ao_iteration in range(1, cfg.max_ao_iterations + 1):
        n_ao = ao_iteration
        if moves:
            res = optimise_positions(
                Q,
                eta,
                objective.value_and_gradients,
                objective.values,
                cons,
                kit.positions,
                max_iterations=cfg.max_position_iterations,
                per_uav_steps=cfg.per_uav_steps,
                values_moving_one=objective.values_moving_one if kit.fast else None,
                **search,
            )
            Q, n_pos = res.point, n_pos + res.iterations
        if how.shares:
            res = optimise_shares(
                Q,
                eta,
                objective.value_and_gradients,
                objective.values,
                cons,
                kit.shares,
                max_iterations=cfg.max_bandwidth_iterations,
                **search,
            )
            eta, n_bw = res.point, n_bw + res.iterations
        f_new = objective.value(Q, eta)
        history.append(f_new)
        decrease = (f - f_new) / f if np.isfinite(f) else np.inf
        f = f_new
        if single is not None and polish and ao_iteration == 1 and decrease > cfg.epsilon:
            # The polish after the first AO iteration (docs/model.md, "The polish"): kept when
            # it gains more than EARLY_POLISH_GAIN on that point; otherwise Algorithm 2 resumes.
            early = polish_nlp(kit).polish(Q, eta, single, cons)
            if early.accepted and f_new - early.value > EARLY_POLISH_GAIN * f_new:
                Q, eta, polished_early = early.uav_xy_m, early.bandwidth_share, True
                note, n_polish = f"{early.note} after AO iteration 1", early.iterations
                history.append(early.value)
                break
            n_early = early.iterations
        if decrease <= cfg.epsilon or not (moves and how.shares):
            break
    violated = cons.describe_violations(Q, eta)
    if not capacity_ok(problem.bs_of_uav, s.K, s.n_a):
        violated.append("14e capacity")
    if violated:
        return best_effort(problem, "infeasible: no plan satisfies " + ", ".join(violated))
    if single is not None and polish and not polished_early:
        polished = polish_nlp(kit).polish(Q, eta, single, cons)
        note, n_polish = polished.note, n_early + polished.iterations
        if polished.accepted:
            Q, eta = polished.uav_xy_m, polished.bandwidth_share
            history.append(polished.value)
        else:
            reason = polished.note
    if single is not None and polish:
        # The other basins: the band's leader moved to another UAV.
        f_best = history[-1]
        for leader, start_eta in screen_leaders(Q, eta, single, f_best):
            other = polish_nlp(kit).polish(Q, start_eta, single, cons)
            n_polish += other.iterations
            if other.accepted and other.value < f_best:
                Q, eta, f_best = other.uav_xy_m, other.bandwidth_share, other.value
                history.append(other.value)
                note = f"{other.note} (leader UAV {leader})"
                reason = ""
    report = SolveReport(
        "ok",
        reason,
        ao_iterations=n_ao,
        position_iterations=n_pos,
        bandwidth_iterations=n_bw,
        solve_s=problem.elapsed_s(),
        objective_history=tuple(float(v) for v in history),
        polish=note,
        polish_iterations=n_polish,
    )
    return problem.plan(Q, eta, report)


def plan_alternating(
    inp: SlotInput, kit: SolverKit, how: Alternation, crb: bool = False
) -> SlotPlan:
    """The slot problem (measurement-only objective with crb) solved by `alternate`, or its best
    effort when the link cannot reach R_th anywhere."""
    problem = build_slot_problem(inp, kit, moves=how.positions, measurement_only=crb)
    no_link = problem.link_infeasible_reason()
    if no_link is not None:
        return best_effort(problem, no_link)
    return alternate(problem, kit, how)


def screen_leaders(
    xy: FloatArray, eta: FloatArray, objective: PlanningObjective, f_plan: float
) -> list[tuple[int, FloatArray]]:
    """The starts (leader j, shares [M]) worth polishing from plan (xy [M, 2], eta [M]) with
    tr(C) f_plan: eta with the leader's and UAV j's shares swapped, best screened value first,
    at most MAX_STARTS, each below SCREEN_RATIO f_plan. Deterministic (ties by UAV index)."""
    M = len(eta)
    lead = int(np.argmax(eta))
    others = [j for j in range(M) if j != lead]
    if not others or not np.isfinite(f_plan):
        return []
    etas = np.repeat(np.asarray(eta, dtype=float)[None], len(others), axis=0)
    for row, j in enumerate(others):
        etas[row, lead], etas[row, j] = eta[j], eta[lead]
    xys = np.broadcast_to(np.asarray(xy, dtype=float), (len(others), *np.shape(xy)))
    values = objective.values(xys, etas)
    order = sorted(range(len(others)), key=lambda r: (values[r], others[r]))
    out = [(others[r], etas[r]) for r in order if values[r] < SCREEN_RATIO * f_plan]
    return out[:MAX_STARTS]


class Proposed(PlansOnceToWarmUp):
    """`proposed`: Algorithm 2, polished (planner.polish), with the leader screen."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        polish = kit.scenario.planner.polish
        return plan_alternating(inp, kit, Alternation(polish=polish))

    def prepare(self, kit: SolverKit) -> None:
        """The polish's NLP built (the warm-up slot need not reach the polish), then one slot
        planned."""
        if kit.scenario.planner.polish:
            polish_nlp(kit)
        super().prepare(kit)


class ProposedSca(PlansOnceToWarmUp):
    """`proposed-sca`: Algorithm 2 as printed, never polished."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        return plan_alternating(inp, kit, Alternation())
