"""The polish: the slot's exact non-convex problem solved by IPOPT from the SCA point.

Algorithm 1's SCA stops at the first point where its convex inner approximation makes no more
progress, which can be short of the slot's optimum. The polish solves the exact problem (P1.1
with the bandwidth shares jointly, i.e. (P1) for the chosen association):

    min_{Q, eta}  tr((J_pred + J_M(Q, eta))^-1)
    s.t.  eta_m R~_m(q_m) >= R_th                 (14a, on the serving BS)
          ||q_m - w_c(m)|| <= d_th                (14b, w_c(m) the BS nearest the SCA point)
          sum eta = 1, eta >= 0                   (14c, 14d)
          ||q_m - q_{m,n-1}|| <= V_max dt         (14h)
          ||q_i - q_j|| >= D_s, ||q_m - k_l|| >= D_s (14i, and the keep-out points)
          ||q_m - p_pred|| >= D_s                 (14j)
          (safety rule on: 14j at the slot's clearance and 14i at D_s + 2 e, both at every leg
          sample of the straight legs with the chord margin; 14a/14b e farther from the BS;
          planning/margins.py, planning/legs.py)
          ||q_m - ballistic_m|| <= r_a            (planner.accel_limit_mps2, when set)
          0 <= q <= area                          (planner.keep_in_area, as variable bounds)

with CasADi's exact first and second derivatives (automatic differentiation) and its bundled IPOPT,
started at the SCA plan. Each problem is built once per scenario, fleet size and number of
keep-out points with symbolic parameters (the slot's data) and re-solved every slot; the
caller keeps the polished plan only if the planner's own exact check (SlotConstraints.feasible)
passes and tr(PCRB) is lower. Iteration caps only: no wall-clock limit.

Variables are scaled: q_m = q_{m,n-1} + L z_m with L = V_max dt (m), so z is O(1); J is Jacobi-
scaled by the SCA point's diagonal and f divided by the SCA value (both parameters), so the
objective is O(1) even where J mixes entries of order 1e20 and 1. Distances are constrained
squared, in units of L^2, tightened by SOLVER_MARGIN_M like the SCA subproblem.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.radar import SensingParams
from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.planning.margins import (
    MIN_SHARE,
    SOLVER_MARGIN_M,
    SafetyMargins,
    leg_samples,
    rule_on,
)
from isac_mission.planning.nlp_model import (
    IpoptFactory,
    NlpRows,
    NlpSolver,
    SolveLock,
    add_clearance_row,
    add_uav_rows,
    information_terms,
    lower_at_rate,
    plain_ipopt,
    straight_leg_point,
)
from isac_mission.tracking.pcrb import PlanningObjective
from isac_mission.types import FloatArray

IPOPT_OPTIONS: dict[str, Any] = {
    "print_level": 0,
    "sb": "yes",
    "tol": 1e-9,
    "acceptable_iter": 0,  # no "acceptable" early stop: converge or hit the cap
    "constr_viol_tol": 1e-9,
    "bound_push": 1e-6,  # start at the SCA point, not pushed into the interior
    "bound_frac": 1e-6,
    "mu_init": 1e-4,  # the start is near-optimal: a small barrier from the first iteration
    "hessian_approximation": "exact",
}
"""IPOPT's options of the polish (max_iter comes from planner.polish_max_iterations)."""


@dataclass(frozen=True)
class PolishResult:
    """One polish solve.

    uav_xy_m [M, 2], bandwidth_share [M]: the NLP's answer (shares renormalised to sum 1);
    value: tr(PCRB) of that answer by PlanningObjective.value; solver_status: IPOPT's
    return_status; iterations: IPOPT iterations; accepted: True when the answer passed the exact
    check and beats the start; note: what happened, for the plan's report.
    """

    uav_xy_m: FloatArray
    bandwidth_share: FloatArray
    value: float
    solver_status: str
    iterations: int
    accepted: bool
    note: str


class PolishNLP:
    """The exact slot problem for M UAVs and n_keep_out keep-out points, built once (symbolic
    parameters) and solved per slot by `polish`."""

    def __init__(
        self,
        scenario: Scenario,
        n_keep_out: int = 0,
        max_iterations: int = 50,
        lock: SolveLock | None = None,
        ipopt: IpoptFactory = plain_ipopt,
    ) -> None:
        """max_iterations: IPOPT's iteration cap (planner.polish_max_iterations); lock: held
        around IPOPT's construction and every solve (SolverKit.solve_lock); ipopt: what builds
        the solver (SolverKit.ipopt)."""
        self.lock: SolveLock = lock if lock is not None else contextlib.nullcontext()
        s = scenario
        M = s.M
        self.scenario = s
        self.n_keep_out = n_keep_out
        self.max_iterations = max_iterations
        self.step_m = s.v_max * s.dt
        L = self.step_m
        z = ca.SX.sym("z", M, 2)
        eta = ca.SX.sym("eta", M)
        prev = ca.SX.sym("prev", M, 2)
        serving = ca.SX.sym("serving", M, 2)
        control = ca.SX.sym("control", M, 2)
        ballistic = ca.SX.sym("ballistic", M, 2)
        accel_r2 = ca.SX.sym("accel_r2")  # (radius / L)^2
        keep_out = ca.SX.sym("keep_out", n_keep_out, 2)
        x_pred = ca.SX.sym("x_pred", 4)
        j_pred = ca.SX.sym("j_pred", 4, 4)
        scale = ca.SX.sym("scale", 4)  # Jacobi scaling 1 / sqrt(diag J) at the SCA point
        f_scale = ca.SX.sym("f_scale")  # f at the SCA point
        # The distances kept at the leg samples (SlotConstraints.sample_clearances_m), squared,
        # in units of L^2: per sample, the target's [M], the keep-out points' [M K], the pairs'.
        S = leg_samples(s)
        clear2 = ca.SX.sym("clear2", S * (M * (1 + n_keep_out) + M * (M - 1) // 2))
        params = [prev, serving, control, ballistic, accel_r2, keep_out, x_pred, j_pred, scale]
        params.append(f_scale)
        self.safety = rule_on(s)
        if self.safety:
            params.append(clear2)
        self._param_shapes = [(p.size1(), p.size2()) for p in params]

        q = prev + L * z
        sensing = SensingParams.from_scenario(s)
        J = j_pred
        for m in range(M):
            J = J + information_terms(q[m, :].T, eta[m], x_pred, sensing)
        D = ca.diag(scale)
        Js = D @ J @ D
        inv = ca.solve(Js, ca.SX.eye(4))
        f_true = ca.dot(scale**2, ca.diag(inv))
        objective = f_true / f_scale

        self.n_samples = leg_samples(s)
        rows = self._constraints(
            q,
            z,
            eta,
            prev,
            serving,
            control,
            ballistic,
            accel_r2,
            keep_out,
            x_pred,
            clear2 if self.safety else None,
        )
        rows.add(ca.sum1(eta), 1.0, 1.0)
        g, lbg, ubg = rows.rows, rows.lower, rows.upper

        x = ca.vertcat(ca.reshape(z, 2 * M, 1), eta)
        p = ca.vertcat(*[ca.reshape(v, -1, 1) for v in params])
        self._lbg = np.array(lbg, dtype=float)
        self._ubg = np.array(ubg, dtype=float)
        self._rate_rows = np.array(rows.rate_rows, dtype=int)
        nlp = {"x": x, "p": p, "f": objective, "g": ca.vertcat(*g)}
        opts: dict[str, Any] = {
            "print_time": False,
            "ipopt": {**IPOPT_OPTIONS, "max_iter": max_iterations},
        }
        with self.lock:
            self.solver: NlpSolver = ipopt("polish", nlp, opts)
        # For tests: the objective tr(C) itself (not divided by f_scale), its gradient and Hessian
        # with respect to x = (z [M, 2] column-major, eta [M]).
        self.objective = ca.Function("f", [x, p], [f_true])
        self.gradient = ca.Function("df", [x, p], [ca.gradient(f_true, x)])
        self.hessian = ca.Function("d2f", [x, p], [ca.hessian(f_true, x)[0]])
        self.constraints = ca.Function("g", [x, p], [ca.vertcat(*g)])

    def _constraints(
        self,
        q: ca.SX,
        z: ca.SX,
        eta: ca.SX,
        prev: ca.SX,
        serving: ca.SX,
        control: ca.SX,
        ballistic: ca.SX,
        accel_r2: ca.SX,
        keep_out: ca.SX,
        x_pred: ca.SX,
        clear2: ca.SX | None,
    ) -> NlpRows:
        """The slot's rows (planning/nlp_model.py): per UAV 14a, 14b, 14h and the dynamics disk,
        then 14j and 14i to the keep-out points at every leg sample tau of the straight legs
        against the constant-velocity target, then 14i between UAVs. With the safety rule the
        distances are the parameters clear2 (`pack`: per sample and row) and 14a/14b hold
        e = the link margin farther from the BS; without it, D_s at the slot instant."""
        s = self.scenario
        M, L = s.M, self.step_m
        e = SafetyMargins.of(s).link_m
        fractions = [(i + 1) / self.n_samples for i in range(self.n_samples)]
        K = self.n_keep_out
        per_sample = M * (1 + K) + M * (M - 1) // 2
        d_safe2 = ((s.d_safe + SOLVER_MARGIN_M) / L) ** 2 if s.d_safe > 0 else 0.0

        def bound(f: int, row: int) -> ca.SX | float:
            return d_safe2 if clear2 is None else clear2[f * per_sample + row]

        def at(m: int, tau: float) -> ca.SX:
            return straight_leg_point(prev[m, :], q[m, :], tau)

        rows = NlpRows()
        for m in range(M):
            qm = q[m, :]
            reach = [ca.sumsqr(qm - ballistic[m, :]) / L**2 - accel_r2]
            step2 = ca.sumsqr(z[m, :])
            add_uav_rows(rows, s, qm, eta[m], serving[m, :], control[m, :], step2, e, L, (), reach)
            for f, tau in enumerate(fractions):
                target = s.motion.position_after(x_pred, (tau - 1.0) * s.dt).T
                add_clearance_row(rows, at(m, tau) - target, bound(f, m), L)
                for k in range(K):
                    add_clearance_row(rows, at(m, tau) - keep_out[k, :], bound(f, M + m * K + k), L)
        pair = 0
        for i in range(M):
            for j in range(i + 1, M):
                for f, tau in enumerate(fractions):
                    gap = at(i, tau) - at(j, tau)
                    add_clearance_row(rows, gap, bound(f, M * (1 + K) + pair), L)
                pair += 1
        return rows

    def pack(
        self, xy: FloatArray, eta: FloatArray, objective: PlanningObjective, cons: SlotConstraints
    ) -> tuple[FloatArray, FloatArray]:
        """(x, p): the NLP's variables for plan (xy [M, 2], eta [M]) and its parameters for
        this slot, with the scalings taken at that plan."""
        s = self.scenario
        M = s.M
        L = self.step_m
        z = (np.asarray(xy, dtype=float) - cons.prev_xy) / L
        x = np.concatenate([z.reshape(-1, order="F"), np.asarray(eta, dtype=float)])
        nearest = np.argmin(
            np.linalg.norm(np.asarray(xy)[:, None, :] - cons.bs_xy[None], axis=-1), axis=1
        )
        if cons.ballistic_xy is None or not np.isfinite(cons.accel_radius_m):
            ballistic, accel_r2 = cons.prev_xy, 4.0  # inactive: 14h already bounds |z| by 1
        else:
            radius = max(cons.accel_radius_m - SOLVER_MARGIN_M, 0.0)
            ballistic, accel_r2 = cons.ballistic_xy, (radius / L) ** 2
        keep_out = np.zeros((0, 2)) if cons.keep_out_xy is None else cons.keep_out_xy
        J = objective._information(np.asarray(xy, dtype=float), np.asarray(eta, dtype=float))[0]
        scale = 1.0 / np.sqrt(np.diag(J))
        f0 = objective.value(xy, eta)
        values = [
            cons.prev_xy,
            cons.serving_bs_xy,
            cons.bs_xy[nearest],
            ballistic,
            np.array([accel_r2]),
            keep_out,
            objective.x_pred,
            objective.J_pred,
            scale,
            np.array([f0 if np.isfinite(f0) and f0 > 0 else 1.0]),
        ]
        if self.safety:
            c_target, c_keep, c_pairs = cons.sample_clearances_m()
            rows = np.hstack([c_target, c_keep.reshape(len(c_target), -1), c_pairs])  # [S, .]
            values.append(((rows.ravel() + SOLVER_MARGIN_M) / L) ** 2)
        p = np.concatenate([np.asarray(v, dtype=float).reshape(-1, order="F") for v in values])
        assert M * 2 + M == len(x)
        return x, p

    def unpack(self, x: FloatArray, cons: SlotConstraints) -> tuple[FloatArray, FloatArray]:
        """(xy [M, 2], eta [M]) of the NLP variables x."""
        M = self.scenario.M
        z = np.asarray(x[: 2 * M]).reshape((M, 2), order="F")
        return cons.prev_xy + self.step_m * z, np.asarray(x[2 * M :], dtype=float)

    def polish(
        self,
        start_xy: FloatArray,
        start_eta: FloatArray,
        objective: PlanningObjective,
        cons: SlotConstraints,
    ) -> PolishResult:
        """Solve from the SCA plan (start_xy [M, 2], start_eta [M]); the result says whether its
        answer is accepted (feasible by cons.feasible and strictly better than the start)."""
        s = self.scenario
        f_start = objective.value(start_xy, start_eta)
        x0, p = self.pack(start_xy, start_eta, objective, cons)
        M = s.M
        lo, hi = cons.area_bounds()
        lbz = (lo[None, :] - cons.prev_xy) / self.step_m
        ubz = (hi[None, :] - cons.prev_xy) / self.step_m
        lbx = np.concatenate([lbz.reshape(-1, order="F"), np.full(M, MIN_SHARE)])
        ubx = np.concatenate([ubz.reshape(-1, order="F"), np.ones(M)])
        x0 = np.clip(x0, lbx, ubx)
        with self.lock:
            lbg = lower_at_rate(self._lbg, self._rate_rows, s.r_th, cons.scenario.r_th)
            sol = self.solver(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=self._ubg)
            stats = self.solver.stats()
        status = str(stats.get("return_status", "unknown"))
        iterations = int(stats.get("iter_count", 0))
        xy, eta = self.unpack(np.asarray(sol["x"], dtype=float).ravel(), cons)
        eta = np.maximum(eta, 0.0)
        eta = eta / eta.sum()
        value = objective.value(xy, eta)

        def result(accepted: bool, note: str) -> PolishResult:
            return PolishResult(xy, eta, value, status, iterations, accepted, note)

        if not stats.get("success", False):
            return result(False, f"polish kept the SCA plan: IPOPT {status} after {iterations} it")
        if not bool(cons.feasible(xy[None], eta[None])[0]):
            bad = ", ".join(cons.describe_violations(xy, eta))
            return result(False, f"polish kept the SCA plan: IPOPT answer violates {bad}")
        if not value < f_start:
            return result(False, "polish kept the SCA plan: no improvement")
        return result(True, f"polished: {f_start:.6g} -> {value:.6g} in {iterations} it")
