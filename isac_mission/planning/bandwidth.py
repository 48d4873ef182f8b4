"""Bandwidth shares (P1.2): descent-direction search with the linearised subproblem (P1.2.1).

(P1.2.1) minimises grad^T eta subject to eta_m >= eta_min_m (20a), sum eta = 1 (14c) and
0 <= eta <= 1 (14d): an LP, built once per M with Parameters (DPP). Its vertex is then line-searched
as in Algorithm 1.
"""

from __future__ import annotations

from collections.abc import Callable

import cvxpy as cp
import numpy as np

from isac_mission.planning.descent import DescentResult, line_search
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.margins import SHARE_MARGIN
from isac_mission.types import FloatArray


class BandwidthSubproblem:
    """(P1.2.1) for M UAVs; `solve` returns eta* [M] or None if sum(eta_min) > 1.

    solver: a cvxpy LP solver, or "closed-form" for the vertex `lp_vertex` (the LP's solution,
    without cvxpy's per-solve overhead; the planner's default, `SolverKit`).
    """

    def __init__(self, n_uavs: int, solver: str = "HIGHS") -> None:
        self.eta = cp.Variable(n_uavs)
        self.direction = cp.Parameter(n_uavs)
        self.floor = cp.Parameter(n_uavs, nonneg=True)
        cons = [self.eta >= self.floor, cp.sum(self.eta) == 1, self.eta <= 1]
        self.problem = cp.Problem(cp.Minimize(self.direction @ self.eta), cons)
        assert self.problem.is_dpp()
        self.solver = solver

    def solve(self, grad: FloatArray, eta_min: FloatArray) -> FloatArray | None:
        """eta* [M] for gradient grad [M] and floors eta_min [M]; None if infeasible."""
        floor = eta_min * (1 + SHARE_MARGIN)
        if floor.sum() > 1.0:
            return None
        if self.solver == "closed-form":
            eta = lp_vertex(grad, eta_min)
            return np.asarray(eta / eta.sum())
        scale = np.max(np.abs(grad))
        self.direction.value = grad / scale if scale > 0 else grad
        self.floor.value = floor
        try:
            self.problem.solve(solver=self.solver)
        except cp.error.SolverError:
            return None
        if self.problem.status != cp.OPTIMAL or self.eta.value is None:
            return None
        eta = np.clip(np.asarray(self.eta.value, dtype=float), floor, 1.0)
        return np.asarray(eta / eta.sum())


def lp_vertex(grad: FloatArray, eta_min: FloatArray) -> FloatArray:
    """Closed-form solution of (P1.2.1): every UAV at its floor, the rest to the steepest one."""
    eta = eta_min * (1 + SHARE_MARGIN)
    eta[int(np.argmin(grad))] += 1.0 - eta.sum()
    return np.asarray(eta)


def starting_candidates(start_eta: FloatArray, eta_min: FloatArray) -> FloatArray:
    """[C, M] feasible starting shares: start_eta, equal shares (if feasible) and the M vertices of
    (P1.2.1)'s feasible set (all UAVs at their floor, the rest to one UAV).

    f is not convex in eta (range information grows as eta^2), so it has a local minimum near each
    vertex; a descent from last slot's shares alone keeps the bandwidth on last slot's UAV.
    """
    M = len(eta_min)
    floor = eta_min * (1 + SHARE_MARGIN)
    vertices = np.tile(floor, (M, 1)) + np.eye(M) * (1.0 - floor.sum())
    cands = [start_eta[None], vertices]
    equal = np.full(M, 1.0 / M)
    if np.all(equal >= floor):
        cands.insert(1, equal[None])
    return np.vstack(cands)


def optimise_shares(
    uav_xy: FloatArray,
    start_eta: FloatArray,
    objective_value_grad: Callable[[FloatArray, FloatArray], tuple[float, FloatArray, FloatArray]],
    objective_values: Callable[[FloatArray, FloatArray], FloatArray],
    constraints: SlotConstraints,
    subproblem: BandwidthSubproblem,
    *,
    epsilon: float,
    step: float,
    max_iterations: int,
) -> DescentResult:
    """Descent search for the shares at fixed positions uav_xy [M, 2] from start_eta [M]."""
    s = constraints.scenario
    eta_min = s.r_th / constraints.full_rates(uav_xy)
    M = uav_xy.shape[0]
    eta = start_eta
    if eta_min.sum() * (1 + SHARE_MARGIN) <= 1.0:
        cands = starting_candidates(start_eta, eta_min)
        at = np.broadcast_to(uav_xy, (len(cands), M, 2))
        ok = constraints.feasible(at, cands)
        values = np.where(ok, objective_values(at, cands), np.inf)
        if np.isfinite(values.min()):
            eta = cands[int(np.argmin(values))]
    f = objective_values(uav_xy[None], eta)[0]
    feasible_now = bool(constraints.feasible(uav_xy[None], eta[None])[0])
    it = 0
    for it in range(1, max_iterations + 1):
        _, _, grad = objective_value_grad(uav_xy, eta)
        target = subproblem.solve(grad, eta_min)
        if target is None:
            it -= 1
            break
        found = line_search(
            eta,
            target,
            step,
            lambda c: objective_values(np.broadcast_to(uav_xy, (len(c), M, 2)), c),
            lambda c: constraints.feasible(np.broadcast_to(uav_xy, (len(c), M, 2)), c),
        )
        if found is None:
            break
        eta_new, f_new = found
        decrease = (f - f_new) / f if feasible_now and np.isfinite(f) else np.inf
        eta, f, feasible_now = eta_new, f_new, True
        if decrease <= epsilon:
            break
    return DescentResult(point=eta, value=float(f), iterations=it, feasible=feasible_now)
