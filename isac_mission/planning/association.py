"""UAV-BS association: the LP relaxation of (P1-F.1), rounded so that N_a still holds.

Each UAV is served by exactly one BS (14f read as an equality: docs/model.md) and a BS serves at most
N_a UAVs (14e). The cost of UAV m on BS k is b_mk = 1 / R~_mk at the UAVs' previous positions.
The LP is a transportation problem, so a vertex solution is integral; the paper's argmax rounding
can still break N_a on ties, and then the integral optimum (an assignment problem over N_a copies of
each BS) replaces it.
"""

from __future__ import annotations

import cvxpy as cp
import numpy as np
from scipy.optimize import linear_sum_assignment

from isac_mission.model.channel import full_band_rate
from isac_mission.model.geometry import uav_bs_distances
from isac_mission.types import FloatArray, IntArray


def association_costs(
    uav_xy: FloatArray, bs_xy: FloatArray, *, dH: float, rho0: float, B: float
) -> FloatArray:
    """b [M, K] = 1 / (B log2(1 + rho0 / (||q_m - w_k||^2 + dH^2))) in s/bit."""
    return np.asarray(1.0 / full_band_rate(uav_bs_distances(uav_xy, bs_xy), dH, rho0, B))


class AssociationLP:
    """(P1-F.1) relaxed to 0 <= a <= 1, built once for (M, K) with the costs as a DPP Parameter."""

    def __init__(
        self, n_uavs: int, n_bs: int, capacity: int, solver: str = "HIGHS", shortcut: bool = True
    ) -> None:
        self.costs = cp.Parameter((n_uavs, n_bs), nonneg=True)
        self.a = cp.Variable((n_uavs, n_bs))
        cons = [
            self.a >= 0,
            self.a <= 1,
            cp.sum(self.a, axis=1) == 1,
            cp.sum(self.a, axis=0) <= capacity,
        ]
        self.problem = cp.Problem(cp.Minimize(cp.sum(cp.multiply(self.costs, self.a))), cons)
        assert self.problem.is_dpp()
        self.capacity = capacity
        self.solver = solver
        # `associate` skips the LP when its optimum is known in closed form (see unique_optimum).
        self.shortcut = shortcut

    def solve(self, costs: FloatArray) -> FloatArray | None:
        """The relaxed solution [M, K], or None if the solver failed."""
        self.costs.value = costs / costs.max()
        try:
            self.problem.solve(solver=self.solver)
        except cp.error.SolverError:
            return None
        if self.problem.status != cp.OPTIMAL or self.a.value is None:
            return None
        return np.asarray(self.a.value, dtype=float)


def unique_optimum(costs: FloatArray, capacity: int) -> IntArray | None:
    """The LP's optimum [M] without solving it, when it is obvious and unique; else None.

    If every UAV has a strict cheapest BS (by a relative 1e-9) and those choices respect the
    capacity, that assignment is feasible and every other feasible (even fractional) point costs
    strictly more, so it is the LP's unique optimum and the rounding keeps it.
    """
    if costs.shape[1] == 1:
        chosen = np.zeros(costs.shape[0], dtype=np.int64)
    else:
        two = np.partition(costs, 1, axis=1)[:, :2]
        if np.any(two[:, 1] <= two[:, 0] * (1 + 1e-9)):
            return None
        chosen = np.asarray(np.argmin(costs, axis=1), dtype=np.int64)
    if np.bincount(chosen, minlength=costs.shape[1]).max() > capacity:
        return None
    return chosen


def optimal_assignment(costs: FloatArray, capacity: int) -> IntArray:
    """The integral optimum of (P1-F.1): BS index [M] per UAV with <= capacity UAVs per BS."""
    expanded = np.repeat(costs, capacity, axis=1)
    rows, cols = linear_sum_assignment(expanded)
    out = np.empty(costs.shape[0], dtype=np.int64)
    out[rows] = cols // capacity
    return out


def round_association(relaxed: FloatArray, costs: FloatArray, capacity: int) -> IntArray:
    """The paper's argmax rounding of a relaxed solution [M, K], repaired if it breaks N_a."""
    chosen = np.asarray(np.argmax(relaxed, axis=1), dtype=np.int64)
    if np.bincount(chosen, minlength=costs.shape[1]).max() <= capacity:
        return chosen
    return optimal_assignment(costs, capacity)


def associate(
    uav_xy: FloatArray,
    bs_xy: FloatArray,
    *,
    capacity: int,
    dH: float,
    rho0: float,
    B: float,
    lp: AssociationLP,
) -> IntArray:
    """The communication-optimal association [M] from the UAVs' previous positions [M, 2]."""
    costs = association_costs(uav_xy, bs_xy, dH=dH, rho0=rho0, B=B)
    if lp.shortcut:
        obvious = unique_optimum(costs, capacity)
        if obvious is not None:
            return obvious
    relaxed = lp.solve(costs)
    if relaxed is None:
        return optimal_assignment(costs, capacity)
    return round_association(relaxed, costs, capacity)
