"""Algorithm 1: descent-direction search for the UAV positions (P1.1).

Each iteration linearises f at Q^(l), solves the convex subproblem (P1.1.2) — linear objective under
19a (rate radius of the current share), the control-range approximation (eq. 21), 14h, and the
first-order inner approximations of 14i and 14j (eq. 22-23; with the safety rule on, at every
sampled instant of the straight legs, planning/legs.py) — then line-searches
Q^(l) + omega (Q* - Q^(l)) over omega in {0, d_omega, ..., 1} keeping only points that satisfy the
original constraints. The cvxpy problem is built once per M with Parameters (DPP) and re-solved.

The rows of eq. 22-23 at every leg sample (`leg_rows`, the safety rule, docs/model.md): a
sample's position tau q + (1 - tau) q_prev is affine in the waypoint q, so each distance
constraint |tau q + (1 - tau) q_prev - u(tau)| >= R is linearised at q^r as eq. 23 is:
2 tau r^T q >= R^2 - |r|^2 + 2 tau r^T q^r, r = tau q^r + (1 - tau) q_prev - u. At tau = 1 these
are eq. 22 and 23 themselves.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable

import clarabel
import cvxpy as cp
import numpy as np
from scipy import sparse

from isac_mission.config import Scenario
from isac_mission.model.channel import rate_radius
from isac_mission.planning.descent import DescentResult, line_search
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.margins import SOLVER_MARGIN_M, SafetyMargins, leg_samples
from isac_mission.types import FloatArray, IntArray

# f of a plan [M, 2] with one UAV m moved to candidates [L, 2]: (current, eta, m, cands) -> [L].
MovingOne = Callable[[FloatArray, FloatArray, int, FloatArray], FloatArray]


class PositionSubproblem:
    """(P1.1.2) for M UAVs as a DPP problem; `solve` returns Q* [M, 2] or None if infeasible."""

    def __init__(
        self, scenario: Scenario, solver: str, direct: bool = True, n_keep_out: int = 0
    ) -> None:
        """solver: a cvxpy SOCP solver name. direct: with CLARABEL, call clarabel directly on
        the same problem written in its conic form (`_solve_clarabel`), skipping cvxpy's
        per-solve parameter mapping (several ms); other solvers always go through cvxpy.
        n_keep_out: fixed points (vehicles outside this plan) every UAV keeps D_s from, as it
        keeps D_s from the target (eq. 23 per point). With the safety rule on, eq. 22 and 23 hold
        at each of the S leg samples (rows repeated per sample) and the control range is
        kept e closer (planning/margins.py)."""
        s = scenario
        M = s.M
        self.scenario = s
        self.n_keep_out = n_keep_out
        self.n_samples = leg_samples(s)
        self.control_radius_m = max(s.d_th - SOLVER_MARGIN_M - SafetyMargins.of(s).link_m, 0.0)
        # The target, then the keep-out points, per leg sample.
        n_points = (1 + n_keep_out) * self.n_samples
        self.solver = solver
        self.direct = direct and solver.upper() == "CLARABEL"
        self.Q = cp.Variable((M, 2))
        self.direction = cp.Parameter((M, 2))
        self.prev = cp.Parameter((M, 2))
        self.serving = cp.Parameter((M, 2))
        self.radius = cp.Parameter(M, nonneg=True)
        self.control_bs = cp.Parameter((M, 2))
        # Row p M + m: UAV m against point p (p = 0 the target).
        self.target_normal = cp.Parameter((n_points * M, 2))
        self.target_rhs = cp.Parameter(n_points * M)
        select = np.tile(np.eye(M), (n_points, 1))
        self.ballistic = cp.Parameter((M, 2))
        self.accel_radius = cp.Parameter(M, nonneg=True)
        # Coordinates are centred on the UAVs' previous positions for solver conditioning.
        cons = [
            cp.norm(self.Q - self.serving, 2, axis=1) <= self.radius,
            cp.norm(self.Q - self.control_bs, 2, axis=1) <= self.control_radius_m,
            cp.norm(self.Q - self.prev, 2, axis=1) <= s.v_max * s.dt - SOLVER_MARGIN_M,
            cp.sum(cp.multiply(self.target_normal, select @ self.Q), axis=1) >= self.target_rhs,
            cp.norm(self.Q - self.ballistic, 2, axis=1) <= self.accel_radius,
        ]
        # The operating area (the vehicles' geofence), shifted like everything else.
        self.area_lo = cp.Parameter((M, 2))
        self.area_hi = cp.Parameter((M, 2))
        cons += [self.Q >= self.area_lo, self.Q <= self.area_hi]
        self.pairs = np.array(np.triu_indices(M, 1)).T  # [P, 2]
        if len(self.pairs):
            P = len(self.pairs)
            D = np.zeros((P, M))
            D[np.arange(P), self.pairs[:, 0]] = 1.0
            D[np.arange(P), self.pairs[:, 1]] = -1.0
            D = np.tile(D, (self.n_samples, 1))  # row f P + p: pair p at leg sample f
            self.pair_normal = cp.Parameter((P * self.n_samples, 2))
            self.pair_rhs = cp.Parameter(P * self.n_samples)
            cons.append(cp.sum(cp.multiply(self.pair_normal, D @ self.Q), axis=1) >= self.pair_rhs)
        objective = cp.Minimize(cp.sum(cp.multiply(self.direction, self.Q)))
        self.problem = cp.Problem(objective, cons)
        assert self.problem.is_dpp()
        self._build_conic_structure()

    def _build_conic_structure(self) -> None:
        """The fixed sparsity pattern of `_solve_clarabel`'s A, built once.

        Entries are listed in a fixed order (rows, cols); `_perm` maps that order to the CSC
        order, so a solve only fills A.data. Rows: 14j (eq. 23) 0..M-1 and the keep-out points
        (the same form) M..(1+L)M-1, repeated per leg sample, 14i (eq. 22) the next P per leg
        sample, the area box (4 per UAV), then
        four 3-d cones per UAV (19a serving disk, eq. 21 control disk, 14h, dynamics disk).
        """
        M = self.scenario.M
        P = len(self.pairs) * self.n_samples
        uav = np.arange(M)
        point_rows = np.arange((1 + self.n_keep_out) * self.n_samples * M)
        point_uav = np.tile(uav, (1 + self.n_keep_out) * self.n_samples)
        rows: list[IntArray] = [point_rows, point_rows]
        cols: list[IntArray] = [2 * point_uav, 2 * point_uav + 1]
        n_lin = len(point_rows)
        if P:
            pr = n_lin + np.arange(P)
            i, j = (
                np.tile(self.pairs[:, 0], self.n_samples),
                np.tile(self.pairs[:, 1], self.n_samples),
            )
            rows += [pr, pr, pr, pr]
            cols += [2 * i, 2 * i + 1, 2 * j, 2 * j + 1]
            n_lin += P
        # Area rows, per UAV: -x >= .., -y, x, y (x' >= lo' as -x' + s = -lo').
        rows.append(n_lin + np.arange(4 * M))
        cols.append(np.column_stack([2 * uav, 2 * uav + 1, 2 * uav, 2 * uav + 1]).ravel())
        n_lin += 4 * M
        self._area_data = np.tile([-1.0, -1.0, 1.0, 1.0], M)
        for n in range(4):
            base = n_lin + 3 * (n * M + uav)  # first row of each UAV's cone
            rows += [base + 1, base + 2]
            cols += [2 * uav, 2 * uav + 1]
        r, c = np.concatenate(rows), np.concatenate(cols)
        tagged = sparse.csc_matrix(
            (np.arange(1.0, len(r) + 1), (r, c)), shape=(n_lin + 12 * M, 2 * M)
        )
        self._perm = np.asarray(tagged.data - 1, dtype=np.int64)
        self._A = tagged
        self._disk_data = np.full(8 * M, -1.0)
        self._P = sparse.csc_matrix((2 * M, 2 * M))
        self._cones = [clarabel.NonnegativeConeT(n_lin)] + [clarabel.SecondOrderConeT(3)] * (4 * M)
        self._settings = clarabel.DefaultSettings()
        self._settings.verbose = False
        # A tighter duality gap than clarabel's default (1e-8): a linear objective on disks is
        # flat along the boundary, so a 1e-8 gap leaves the point millimetres from the optimum.
        # Feasibility stays at 1e-8: tighter, clarabel stalls at M = 24 (AlmostSolved after
        # 100-200 iterations). The measurements: docs/decisions/0004-planner-fast-paths.md.
        self._settings.tol_gap_abs = 1e-11
        self._settings.tol_gap_rel = 1e-11

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
        v: dict[str, FloatArray] = {}
        v["direction"] = grad / scale if scale > 0 else grad
        v["prev"] = origin.prev_xy - c
        v["serving"] = origin.serving_bs_xy - c
        link = origin.margins.link_m
        radius = rate_radius(eta, s.r_th, s.dH, s.rho0, s.B) - SOLVER_MARGIN_M
        v["radius"] = np.maximum(radius - link if link else radius, 0.0)
        nearest = np.argmin(
            np.linalg.norm(origin.prev_xy[:, None, :] - origin.bs_xy[None], axis=-1), axis=1
        )
        v["control_bs"] = origin.bs_xy[nearest] - c
        if origin.ballistic_xy is None:  # inactive: the 14h disk already bounds the step
            v["ballistic"] = origin.prev_xy - c
            v["accel_radius"] = np.full(s.M, s.v_max * s.dt)
        else:
            v["ballistic"] = origin.ballistic_xy - c
            v["accel_radius"] = np.full(s.M, max(origin.accel_radius_m - SOLVER_MARGIN_M, 0.0))
        lo, hi = origin.area_bounds()
        v["area_lo"] = np.tile(lo - c, (s.M, 1))
        v["area_hi"] = np.tile(hi - c, (s.M, 1))
        lin = lin_xy - c
        if self.n_keep_out:
            keep_out = origin.keep_out_xy
            if keep_out is None or len(keep_out) != self.n_keep_out:
                raise ValueError(f"expected {self.n_keep_out} keep-out points, got {keep_out}")
        if origin.checks_legs:  # the safety rule (the same rows as below when S = 1, e = 0)
            v.update(leg_rows(origin, self.pairs, self.n_keep_out, lin, c, SOLVER_MARGIN_M))
        else:  # the paper's D_s at the slot instant
            points = origin.target_xy[None]
            if self.n_keep_out:
                points = np.vstack([points, np.asarray(origin.keep_out_xy)])
            ds2 = (s.d_safe + SOLVER_MARGIN_M) ** 2
            # Row p M + m: lin_m - point_p.
            diff_t = np.tile(lin, (len(points), 1)) - np.repeat(points - c, s.M, axis=0)
            lin_rows = np.tile(lin, (len(points), 1))
            # ||q^r - u||^2 + 2 (q^r - u)^T (q - q^r) >= D_s^2  (eq. 23)
            v["target_normal"] = 2.0 * diff_t
            v["target_rhs"] = (
                ds2 - np.sum(diff_t**2, axis=1) + 2.0 * np.sum(diff_t * lin_rows, axis=1)
            )
            if len(self.pairs):
                diff_p = lin[self.pairs[:, 0]] - lin[self.pairs[:, 1]]
                # 2 (q_i^r - q_j^r)^T (q_i - q_j) - ||q_i^r - q_j^r||^2 >= D_s^2  (eq. 22)
                v["pair_normal"] = 2.0 * diff_p
                v["pair_rhs"] = ds2 + np.sum(diff_p**2, axis=1)
        if self.direct:
            return self._solve_clarabel(v, c)
        for name, value in v.items():
            getattr(self, name).value = value
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

    def _solve_clarabel(self, v: dict[str, FloatArray], shift: FloatArray) -> FloatArray | None:
        """The same problem, with the Parameter values v (by attribute name), in clarabel's conic
        form min q^T x s.t. A x + s = b, s in (nonnegative orthant) x (3-d second-order cones)^4M.

        x = vec(Q) row by row; a linear row n^T Q_m >= r is s = n^T Q_m - r >= 0; a disk
        ||Q_m - c|| <= rad is s = (rad, Q_m - c) in the SOC. Accepted statuses match cvxpy's
        OPTIMAL / OPTIMAL_INACCURATE (Solved / AlmostSolved).
        """
        s = self.scenario
        M = s.M
        normal_t = v["target_normal"]
        data = [-normal_t[:, 0], -normal_t[:, 1]]
        b_parts = [-v["target_rhs"]]
        if len(self.pairs):
            normal = v["pair_normal"]
            data += [-normal[:, 0], -normal[:, 1], normal[:, 0], normal[:, 1]]
            b_parts.append(-v["pair_rhs"])
        data.append(self._area_data)
        b_parts.append(np.column_stack([-v["area_lo"], v["area_hi"]]).ravel())
        disks = [
            (v["serving"], v["radius"]),
            (v["control_bs"], np.full(M, self.control_radius_m)),
            (v["prev"], np.full(M, s.v_max * s.dt - SOLVER_MARGIN_M)),
            (v["ballistic"], v["accel_radius"]),
        ]
        for centre, rad in disks:
            b_parts.append(np.column_stack([rad, -centre[:, 0], -centre[:, 1]]).ravel())
        A = self._A
        A.data = np.concatenate([*data, self._disk_data])[self._perm]
        cones, settings = self._cones, self._settings
        try:
            solver = clarabel.DefaultSolver(
                self._P,
                v["direction"].ravel(),
                A,
                np.concatenate(b_parts),
                cones,
                settings,
            )
            sol = solver.solve()
        except Exception:  # clarabel raises plain exceptions on bad data
            return None
        if str(sol.status) not in ("Solved", "AlmostSolved"):
            return None
        return np.asarray(np.asarray(sol.x, dtype=float).reshape(M, 2) + shift)


def _per_uav_refinement(
    start: FloatArray,
    target: FloatArray,
    current: FloatArray,
    f_current: float,
    step: float,
    eta: FloatArray,
    objective_values: Callable[[FloatArray, FloatArray], FloatArray],
    constraints: SlotConstraints,
    values_moving_one: MovingOne | None = None,
) -> tuple[FloatArray, float]:
    """One pass over the UAVs: UAV m's position on its own segment start_m -> target_m, the
    others held at `current`; every candidate is checked against the original constraints.

    The paper's single step omega couples all UAVs: a UAV whose gradient is small moves only as
    far as the dominant UAV wants, and the relative-decrease stop then ends the search early.

    `current` is feasible (the common line search's answer), so a candidate that moves UAV m only
    is checked on the constraints involving m (`SlotConstraints.feasible_moving_one`, the same
    answer) when values_moving_one(current, eta, m, cands_m) -> [L] is given, which evaluates f
    with the other UAVs' information summed once instead of the full batch.
    """
    omegas = np.unique(np.append(np.arange(0.0, 1.0, step), 1.0))
    Q, f = current, f_current
    for m in range(Q.shape[0]):
        moved = start[m] + omegas[:, None] * (target[m] - start[m])
        cands = np.repeat(Q[None], len(omegas), axis=0)
        cands[:, m] = moved
        if values_moving_one is None:  # the reference path: every constraint of every UAV
            ok = constraints.feasible(cands, np.broadcast_to(eta, cands.shape[:2]))
        else:
            ok = constraints.feasible_moving_one(Q, eta, m, moved)
        if not np.any(ok):
            continue
        f_cands = (
            objective_values(cands, eta)
            if values_moving_one is None
            else values_moving_one(Q, eta, m, moved)
        )
        values = np.where(ok, f_cands, np.inf)
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
    values_moving_one: MovingOne | None = None,
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
                Q, target, Q_new, f_new, step, eta, objective_values, constraints, values_moving_one
            )
        decrease = (f - f_new) / f if feasible_now and np.isfinite(f) else np.inf
        Q, f, feasible_now = Q_new, f_new, True
        if decrease <= epsilon:
            break
    return DescentResult(point=Q, value=float(f), iterations=it, feasible=feasible_now)


def leg_rows(
    origin: SlotConstraints,
    pairs: IntArray,
    n_keep_out: int,
    lin: FloatArray,
    shift: FloatArray,
    solver_margin_m: float,
) -> dict[str, FloatArray]:
    """The Parameter values target_normal [S (1 + L) M, 2], target_rhs, pair_normal [S P, 2]
    and pair_rhs (row order: sample, then point or pair, then UAV) linearised at lin [M, 2],
    in coordinates shifted by `shift` [2]; pairs [P, 2] the UAV index pairs; R the per-sample
    clearances (SlotConstraints.sample_clearances_m) plus solver_margin_m."""
    M = origin.scenario.M
    c_target, c_keep, c_pairs = origin.sample_clearances_m()  # [S, M], [S, M, K], [S, P]
    prev = origin.prev_xy - shift
    target = origin.target_points() - shift  # [S, 2]
    keep = np.zeros((0, 2)) if not n_keep_out else np.asarray(origin.keep_out_xy) - shift
    lin_rows = np.tile(lin, (1 + len(keep), 1))
    normals, rhs, pair_normals, pair_rhs = [], [], [], []
    for f, tau in enumerate(origin.leg_fractions):
        points = np.vstack([target[f][None], keep])  # [1 + L, 2]
        at = tau * lin + (1.0 - tau) * prev  # the sample's position at the linearisation point
        r = np.tile(at, (len(points), 1)) - np.repeat(points, M, axis=0)
        radii2 = (np.concatenate([c_target[f], c_keep[f].T.ravel()]) + solver_margin_m) ** 2
        normals.append(2.0 * tau * r)
        rhs.append(radii2 - np.sum(r**2, axis=1) + 2.0 * tau * np.sum(r * lin_rows, axis=1))
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            rp = at[i] - at[j]
            pair_normals.append(2.0 * tau * rp)
            pair_rhs.append(
                (c_pairs[f] + solver_margin_m) ** 2
                - np.sum(rp**2, axis=1)
                + 2.0 * tau * np.sum(rp * (lin[i] - lin[j]), axis=1)
            )
    out = {"target_normal": np.vstack(normals), "target_rhs": np.concatenate(rhs)}
    if len(pairs):
        out["pair_normal"] = np.vstack(pair_normals)
        out["pair_rhs"] = np.concatenate(pair_rhs)
    return out
