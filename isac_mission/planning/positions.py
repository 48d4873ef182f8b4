"""Algorithm 1: descent-direction search for the UAV positions (P1.1).

Each iteration linearises f at Q^(l), solves the convex subproblem (P1.1.2) — linear objective under
19a (rate radius of the current share), the control-range approximation (eq. 21), 14h, and the
first-order inner approximations of 14i and 14j (eq. 22-23) — then line-searches
Q^(l) + omega (Q* - Q^(l)) over omega in {0, d_omega, ..., 1} keeping only points that satisfy the
original constraints. The cvxpy problem is built once per M with Parameters (DPP) and re-solved.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.channel import rate_radius
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.types import BoolArray, FloatArray

# Constraints of the convex subproblem are tightened by this much (m) so that a solver answer
# within its own tolerance still satisfies the original constraints exactly.
SOLVER_MARGIN_M = 1e-3


class PositionSubproblem:
    """(P1.1.2) for M UAVs as a DPP problem; `solve` returns Q* [M, 2] or None if infeasible."""

    def __init__(self, scenario: Scenario, solver: str) -> None:
        s = scenario
        M = s.M
        self.scenario = s
        self.solver = solver
        self.Q = cp.Variable((M, 2))
        self.direction = cp.Parameter((M, 2))
        self.prev = cp.Parameter((M, 2))
        self.serving = cp.Parameter((M, 2))
        self.radius = cp.Parameter(M, nonneg=True)
        self.control_bs = cp.Parameter((M, 2))
        self.target_normal = cp.Parameter((M, 2))
        self.target_rhs = cp.Parameter(M)
        self.ballistic = cp.Parameter((M, 2))
        self.accel_radius = cp.Parameter(M, nonneg=True)
        # Coordinates are centred on the UAVs' previous positions for solver conditioning.
        cons = [
            cp.norm(self.Q - self.serving, 2, axis=1) <= self.radius,
            cp.norm(self.Q - self.control_bs, 2, axis=1) <= max(s.d_th - SOLVER_MARGIN_M, 0.0),
            cp.norm(self.Q - self.prev, 2, axis=1) <= s.v_max * s.dt - SOLVER_MARGIN_M,
            cp.sum(cp.multiply(self.target_normal, self.Q), axis=1) >= self.target_rhs,
            cp.norm(self.Q - self.ballistic, 2, axis=1) <= self.accel_radius,
        ]
        self.pairs = np.array(np.triu_indices(M, 1)).T  # [P, 2]
        if len(self.pairs):
            P = len(self.pairs)
            D = np.zeros((P, M))
            D[np.arange(P), self.pairs[:, 0]] = 1.0
            D[np.arange(P), self.pairs[:, 1]] = -1.0
            self.pair_normal = cp.Parameter((P, 2))
            self.pair_rhs = cp.Parameter(P)
            cons.append(cp.sum(cp.multiply(self.pair_normal, D @ self.Q), axis=1) >= self.pair_rhs)
        objective = cp.Minimize(cp.sum(cp.multiply(self.direction, self.Q)))
        self.problem = cp.Problem(objective, cons)
        assert self.problem.is_dpp()

    def solve(
        self,
        grad: FloatArray,
        lin_xy: FloatArray,
        origin: SlotConstraints,
        eta: FloatArray,
    ) -> FloatArray | None:
        """Q* [M, 2] for gradient grad [M, 2] linearised at lin_xy [M, 2], or None."""
        s = self.scenario
        c = origin.prev_xy.mean(axis=0)  # shift for conditioning
        scale = np.max(np.abs(grad))
        self.direction.value = grad / scale if scale > 0 else grad
        self.prev.value = origin.prev_xy - c
        self.serving.value = origin.serving_bs_xy - c
        self.radius.value = np.maximum(
            rate_radius(eta, s.r_th, s.dH, s.rho0, s.B) - SOLVER_MARGIN_M, 0.0
        )
        nearest = np.argmin(
            np.linalg.norm(origin.prev_xy[:, None, :] - origin.bs_xy[None], axis=-1), axis=1
        )
        self.control_bs.value = origin.bs_xy[nearest] - c
        if origin.ballistic_xy is None:  # inactive: the 14h disk already bounds the step
            self.ballistic.value = origin.prev_xy - c
            self.accel_radius.value = np.full(s.M, s.v_max * s.dt)
        else:
            self.ballistic.value = origin.ballistic_xy - c
            self.accel_radius.value = np.full(
                s.M, max(origin.accel_radius_m - SOLVER_MARGIN_M, 0.0)
            )
        lin = lin_xy - c
        tgt = origin.target_xy - c
        ds2 = (s.d_safe + SOLVER_MARGIN_M) ** 2
        diff_t = lin - tgt[None]
        # ||q^r - u||^2 + 2 (q^r - u)^T (q - q^r) >= D_s^2  (eq. 23)
        self.target_normal.value = 2.0 * diff_t
        self.target_rhs.value = ds2 - np.sum(diff_t**2, axis=1) + 2.0 * np.sum(diff_t * lin, axis=1)
        if len(self.pairs):
            diff_p = lin[self.pairs[:, 0]] - lin[self.pairs[:, 1]]
            # 2 (q_i^r - q_j^r)^T (q_i - q_j) - ||q_i^r - q_j^r||^2 >= D_s^2  (eq. 22)
            self.pair_normal.value = 2.0 * diff_p
            self.pair_rhs.value = ds2 + np.sum(diff_p**2, axis=1)
        try:
            with warnings.catch_warnings():
                # OPTIMAL_INACCURATE is accepted: the line search re-checks every candidate.
                warnings.simplefilter("ignore", UserWarning)
                self.problem.solve(solver=self.solver)
        except cp.error.SolverError:
            return None
        if self.problem.status not in (cp.OPTIMAL, cp.OPTIMAL_INACCURATE) or self.Q.value is None:
            return None
        return np.asarray(np.asarray(self.Q.value, dtype=float) + c)


@dataclass(frozen=True)
class DescentResult:
    """Outcome of a descent search: best point, its objective, iterations, whether it is feasible."""

    point: FloatArray
    value: float
    iterations: int
    feasible: bool


def line_search(
    start: FloatArray,
    target: FloatArray,
    step: float,
    values: Callable[[FloatArray], FloatArray],
    feasible: Callable[[FloatArray], BoolArray],
) -> tuple[FloatArray, float] | None:
    """argmin over omega in {0, step, ..., 1} of f(start + omega (target - start)) among feasible
    candidates; None if none is feasible. start/target are arrays of any equal shape."""
    omegas = np.unique(np.append(np.arange(0.0, 1.0, step), 1.0))
    cands = start[None] + omegas.reshape((-1,) + (1,) * start.ndim) * (target - start)[None]
    ok = feasible(cands)
    if not np.any(ok):
        return None
    f = values(cands)
    f = np.where(ok, f, np.inf)
    i = int(np.argmin(f))
    if not np.isfinite(f[i]):
        return None
    return cands[i], float(f[i])


def _per_uav_refinement(
    start: FloatArray,
    target: FloatArray,
    current: FloatArray,
    f_current: float,
    step: float,
    eta: FloatArray,
    objective_values: Callable[[FloatArray, FloatArray], FloatArray],
    constraints: SlotConstraints,
) -> tuple[FloatArray, float]:
    """One pass over the UAVs: UAV m's position on its own segment start_m -> target_m, the
    others held at `current`; every candidate is checked against the original constraints.

    The paper's single step omega couples all UAVs: a UAV whose gradient is small moves only as
    far as the dominant UAV wants, and the relative-decrease stop then ends the search early.
    """
    omegas = np.unique(np.append(np.arange(0.0, 1.0, step), 1.0))
    Q, f = current, f_current
    for m in range(Q.shape[0]):
        cands = np.repeat(Q[None], len(omegas), axis=0)
        cands[:, m] = start[m] + omegas[:, None] * (target[m] - start[m])
        ok = constraints.feasible(cands, np.broadcast_to(eta, cands.shape[:2]))
        if not np.any(ok):
            continue
        values = np.where(ok, objective_values(cands, eta), np.inf)
        i = int(np.argmin(values))
        if values[i] < f:
            Q, f = cands[i], float(values[i])
    return Q, f


def optimise_positions(
    start_xy: FloatArray,
    eta: FloatArray,
    objective_value_grad: Callable[[FloatArray, FloatArray], tuple[float, FloatArray, FloatArray]],
    objective_values: Callable[[FloatArray, FloatArray], FloatArray],
    constraints: SlotConstraints,
    subproblem: PositionSubproblem,
    *,
    epsilon: float,
    step: float,
    max_iterations: int,
    per_uav_steps: bool = True,
) -> DescentResult:
    """Algorithm 1 from start_xy [M, 2] at fixed shares eta [M].

    per_uav_steps: after the common line search, line-search each UAV's own step along its
    direction with the others fixed (docs/model.md, "Per-UAV steps"); False is the paper as printed.
    """
    Q = start_xy
    f = objective_values(Q[None], eta)[0]
    feasible_now = bool(constraints.feasible(Q[None], eta[None])[0])
    it = 0
    for it in range(1, max_iterations + 1):
        _, grad, _ = objective_value_grad(Q, eta)
        target = subproblem.solve(grad, Q, constraints, eta)
        if target is None:
            it -= 1
            break
        found = line_search(
            Q,
            target,
            step,
            lambda c: objective_values(c, eta),
            lambda c: constraints.feasible(c, np.broadcast_to(eta, c.shape[:2])),
        )
        if found is None:
            break
        Q_new, f_new = found
        if per_uav_steps:
            Q_new, f_new = _per_uav_refinement(
                Q, target, Q_new, f_new, step, eta, objective_values, constraints
            )
        decrease = (f - f_new) / f if feasible_now and np.isfinite(f) else np.inf
        Q, f, feasible_now = Q_new, f_new, True
        if decrease <= epsilon:
            break
    return DescentResult(point=Q, value=float(f), iterations=it, feasible=feasible_now)
