"""The receding-horizon problem of slots n..n+L-1 as one NLP, built once and solved by IPOPT.

    min  sum_l w_l tr(C_l),  C_l = (J_pred,l + J_M(Q_l, eta_l; x_l))^-1,
         J_pred,1 = the slot's prior information, J_pred,l+1 = (F C_l F^T + W)^-1,
         x_l = F^(l-1) x_pred (the constant-velocity prediction)
    s.t. for every horizon slot l and UAV m (slot n's association kept over the horizon):
         eta_lm R~(|q_lm - w_k(m)| + e) >= R_th                       (14a, with the link margin)
         |q_lm - w_c(m)| + e <= d_th                                   (14b)
         sum_m eta_lm = 1, eta_lm >= 0                                 (14c, 14d)
         |q_lm - q_l-1,m| <= V_max dt                                  (14h)
         vehicle model: also the Hermite leg (q, v)_l-1 -> (q, v)_l within a_max and V_max
         at leg_samples points s of each leg: |q_m(s) - p(s)| >= c_l   (14j, c_l the clearance)
                                              |q_i(s) - q_j(s)| >= D_s + 2e, |q_m(s) - k| >= D_s + 2e
         0 <= q_lm <= area                                             (operating area, bounds)

with w_l = discount^(l-1) (times terminal_weight on the last slot). The derivatives are exact:
CasADi's automatic differentiation, but the Lagrangian's Hessian is assembled through each
slot's information (planning/horizon_hessian.py: the same matrix at 0.4 of the operations at
M = 24). Everything that changes per slot is a parameter: the UAVs' positions and velocities, the
serving and control BSs, the keep-out points, the predicted state, the prior information, the
clearances c_l and the objective's scale.

Lifted: what IPOPT solves has the scaled predicted covariance Pt_l = E_l P_l+1 E_l of every horizon
slot but the last as 16 variables, with the explicit equality Pt_l = E_l (F C_l F^T + W) E_l, and
slot l + 1 builds its prior on E_l Pt_l^-1 E_l: the same problem (eliminating Pt gives it back),
whose Hessian has one block per slot instead of one dense block over the horizon (docs/model.md,
"Receding horizon"). `objective` and `gradient` are the eliminated form.

Scaling: q_lm = q_m,n-1 + S z_lm with S = V_max dt; v_lm = V_max u_lm; D_l = diag(1 / sqrt(diag
J_l)) and E_l = diag(1 / sqrt(diag P_l+1)) taken at the start point (parameters); the objective
is divided by its value at the start point. Distances are constrained squared in units of S^2,
tightened by SOLVER_MARGIN_M.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import casadi as ca
import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.vehicle import end_accelerations, hermite_position, velocity_control_points
from isac_mission.planning.horizon_hessian import LiftedSlot, horizon_hess_lag, vech
from isac_mission.planning.legs import chord_point_clearance_m
from isac_mission.planning.margins import (
    MIN_SHARE,
    SafetyMargins,
    sag_m,
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
    scaled_inverse_sx,
    straight_leg_point,
)
from isac_mission.tracking.pcrb import (
    SensingParams,
    bound_along,
)
from isac_mission.types import FloatArray, HorizonDuals, IntArray

IPOPT_OPTIONS: dict[str, Any] = {
    "print_level": 0,
    "sb": "yes",
    "tol": 1e-7,
    "constr_viol_tol": 1e-8,
    "acceptable_iter": 0,
    # Stop at the barrier problem of mu = 3e-5 (an interior plan, every row a little slack)
    # instead of driving mu to 1e-9: once mu_init's problem was solved, the drop to 1e-6 cost
    # most capped solves their last 15 iterations and left an iterate outside the rows
    # (docs/model.md, "At the barrier target").
    "mu_target": 3e-5,
    # The start (shifted horizon or per-slot plan) is near a solution: a small, monotone barrier
    # from the first iteration and no push into the interior. The adaptive barrier wandered off
    # (mu up to 1e3, steps of 1e6) and hit the iteration cap on 14 % of paper.yaml's slots.
    "mu_strategy": "monotone",
    "mu_init": 1e-4,
    "bound_push": 1e-6,
    "bound_frac": 1e-6,
    "hessian_approximation": "exact",
    # MUMPS without its own scalings of the KKT matrix (IPOPT's defaults: chosen automatically,
    # a permutation by weighted matching and a scaling): the same iterates to 1e-6 in the
    # scaled variables and iteration counts on recorded slots of the 24-UAV fleet, at 20 ms an
    # iteration instead of 34 (docs/performance.md, "The KKT matrix unscaled").
    "mumps_permuting_scaling": 0,
    "mumps_scaling": 0,
}
"""IPOPT's options of the horizon (max_iter from planner.horizon.max_iterations)."""

WARM_START_OPTIONS: dict[str, Any] = {
    "warm_start_init_point": "yes",
    "warm_start_bound_push": 1e-3,
    "warm_start_bound_frac": 1e-3,
    "warm_start_slack_bound_push": 1e-3,
    "warm_start_slack_bound_frac": 1e-3,
    "warm_start_mult_bound_push": 1e-3,
}
"""IPOPT's options on top of IPOPT_OPTIONS for a start from last slot's multipliers, shifted with
its plan (`warm_duals`): from the shifted plan alone IPOPT took a median 77 iterations in the
soak's tracking phase (docs/model.md, "Start points"). A cold start (no multipliers, or another
problem's) keeps IPOPT's own initialisation: with zero multipliers pushed to these bounds the
starts from rest stalled."""


def lifted_slot(
    J_prior: ca.SX,
    scale_j: ca.SX,
    scale_p: ca.SX,
    Pt: ca.SX | None,
    weight: float,
    F: FloatArray,
    W: FloatArray,
    J_info: ca.SX,
) -> tuple[ca.SX, ca.SX | None]:
    """One slot of the lifted recursion: (weight tr(C), vec(E (F C F^T + W) E - Pt) [16], None on
    the last slot: Pt None) with C = (J_prior + J_info)^-1 [4, 4] (Jacobi-scaled by scale_j [4])
    and E = diag(scale_p [4])."""
    J = J_prior + J_info
    C = scaled_inverse_sx(0.5 * (J + J.T), scale_j)
    term = weight * ca.trace(C)
    if Pt is None:
        return term, None
    E = ca.diag(scale_p)
    P = ca.mtimes(ca.mtimes(ca.DM(F), C), ca.DM(F.T)) + ca.DM(W)
    return term, ca.vec(ca.mtimes(ca.mtimes(E, P), E) - Pt)


def horizon_weights(length: int, discount: float, terminal_weight: float) -> FloatArray:
    """w [L]: discount^l (l = 0..L-1), the last one times terminal_weight."""
    w = discount ** np.arange(length, dtype=float)
    w[-1] *= terminal_weight
    return np.asarray(w)


@dataclass(frozen=True)
class HorizonSlotData:
    """One slot's parameters of the horizon NLP.

    prev_xy [M, 2] (m), prev_velocity [M, 2] (m/s; zeros for the paper's kinematics);
    serving_xy, control_xy [M, 2]: the serving BS (14a) and the control BS (14b) per UAV;
    keep_out_xy [n_keep_out, 2]; x_pred [4]: slot n's predicted target state; J_pred [4, 4];
    clearance_m [L]: the 14j distance per horizon slot; rate_min_bps: R_th (bit/s), the planning
    scenario's (an operator may change it; the NLP takes it as a bound: `_lower`).
    """

    rate_min_bps: float
    prev_xy: FloatArray
    prev_velocity: FloatArray
    serving_xy: FloatArray
    control_xy: FloatArray
    keep_out_xy: FloatArray
    x_pred: FloatArray
    J_pred: FloatArray
    clearance_m: FloatArray

    def in_order(self, order: IntArray) -> HorizonSlotData:
        """The same slot with UAV order[a] in the NLP's UAV slot a."""
        return replace(
            self,
            prev_xy=self.prev_xy[order],
            prev_velocity=self.prev_velocity[order],
            serving_xy=self.serving_xy[order],
            control_xy=self.control_xy[order],
        )


@dataclass(frozen=True)
class HorizonSolution:
    """uav_xy_m [L, M, 2], uav_velocity_mps [L, M, 2] or None, bandwidth_share [L, M] (each row
    renormalised to sum 1); status: IPOPT's return_status; success; iterations; lam_x, lam_g:
    IPOPT's multipliers (the NLP's order of the fleet, its scaled units); f_scale: the
    objective's divisor of this solve."""

    uav_xy_m: FloatArray
    uav_velocity_mps: FloatArray | None
    bandwidth_share: FloatArray
    status: str
    success: bool
    iterations: int
    lam_x: FloatArray
    lam_g: FloatArray
    f_scale: float

    def in_order(self, order: IntArray) -> HorizonSolution:
        """The same plan with the UAVs in `order` (UAV slot a holds UAV order[a])."""
        velocity = self.uav_velocity_mps
        return replace(
            self,
            uav_xy_m=self.uav_xy_m[:, order],
            uav_velocity_mps=None if velocity is None else velocity[:, order],
            bandwidth_share=self.bandwidth_share[:, order],
        )


class HorizonNLP:
    """The horizon problem for the scenario's M UAVs and n_keep_out keep-out points."""

    def __init__(
        self,
        scenario: Scenario,
        n_keep_out: int = 0,
        lock: SolveLock | None = None,
        ipopt: IpoptFactory = plain_ipopt,
        pair_band: int | None = None,
    ) -> None:
        """lock: held around IPOPT's construction and every solve (SolverKit.solve_lock); ipopt:
        what builds the solver (SolverKit.ipopt); pair_band: the UAV-UAV rows only of the UAV
        slots a < b with b - a <= pair_band (planning/pairs.py; the caller orders the fleet so
        that every pair within reach is among them), None: every pair."""
        lock = lock if lock is not None else contextlib.nullcontext()
        s = scenario
        cfg = s.planner.horizon
        M, L, K = s.M, cfg.length, cfg.leg_samples
        self.scenario = s
        self.n_keep_out = n_keep_out
        self.pair_band = band = M - 1 if pair_band is None else min(pair_band, M - 1)
        self.length = L
        self.vehicle_model = s.planner.vehicle_model
        self.step_m = S = s.v_max * s.dt
        margins = SafetyMargins.of(s)
        self.margins = margins
        self._sensing = SensingParams.from_scenario(s)
        dt = s.dt
        motion = s.motion
        F = motion.transition(dt)
        W = motion.process_noise(dt)

        z = ca.SX.sym("z", L * M * 2)
        u = ca.SX.sym("u", L * M * 2) if self.vehicle_model else ca.SX.sym("u", 0)
        eta = ca.SX.sym("eta", L * M)
        prev = ca.SX.sym("prev", M * 2)
        v0 = ca.SX.sym("v0", M * 2)
        serving = ca.SX.sym("serving", M * 2)
        control = ca.SX.sym("control", M * 2)
        keep_out = ca.SX.sym("keep_out", n_keep_out * 2)
        x_pred = ca.SX.sym("x_pred", 4)
        j_pred = ca.SX.sym("j_pred", 4, 4)
        clearance = ca.SX.sym("clearance", L)
        # Jacobi scalings (numbers taken at the start point, so no derivative runs through
        # them): 1 / sqrt(diag J_l) and 1 / sqrt(diag P_l+1) of the bound's recursion.
        scale_j = ca.SX.sym("scale_j", 4 * L)
        scale_p = ca.SX.sym("scale_p", 4 * L)
        f_scale = ca.SX.sym("f_scale")
        params = [prev, v0, serving, control, keep_out, x_pred, ca.reshape(j_pred, 16, 1)]
        params += [clearance, scale_j, scale_p, f_scale]
        self._param_sizes = [int(p.numel()) for p in params]

        def q(h: int, m: int) -> ca.SX:  # position [2] at the end of horizon slot h (0-based)
            if h < 0:
                return prev[2 * m : 2 * m + 2]
            i = 2 * (h * M + m)
            return prev[2 * m : 2 * m + 2] + S * z[i : i + 2]

        def v(h: int, m: int) -> ca.SX:  # velocity [2] there (vehicle model only)
            if h < 0:
                return v0[2 * m : 2 * m + 2]
            i = 2 * (h * M + m)
            return s.v_max * u[i : i + 2]

        def along(h: int, m: int, frac: float) -> ca.SX:  # position on leg h at fraction frac
            if self.vehicle_model:
                leg = hermite_position(q(h - 1, m), v(h - 1, m), q(h, m), v(h, m), dt, frac)
                return ca.SX(leg)
            return straight_leg_point(q(h - 1, m), q(h, m), frac)

        def sq(d: ca.SX) -> ca.SX:
            return ca.sumsqr(d) / S**2

        rows = NlpRows()
        add = rows.add

        e = margins.link_m
        # Between two samples a leg may come closer than at either (docs/model.md, "Safety"):
        # the samples keep the chord's distance, plus the curve's sag off its chord.
        gap_s = dt / K
        sag = sag_m(s.a_max, gap_s) if self.vehicle_model else 0.0
        sep = margins.separation_m if s.d_safe > 0 else 0.0
        keep2 = ((float(chord_point_clearance_m(sep, s.v_max * gap_s)) + sag) / S) ** 2
        self.pair_clearance_m = float(chord_point_clearance_m(sep, 2 * s.v_max * gap_s)) + 2 * sag
        """The distance the UAV-UAV rows keep at each leg sample, m."""
        pair2 = (self.pair_clearance_m / S) ** 2
        fracs = [(k + 1) / K for k in range(K)]
        weights = horizon_weights(L, cfg.discount, cfg.terminal_weight)
        # The bound's recursion lifted (docs/model.md, "Receding horizon"): the scaled predicted
        # covariance Pt_h = E_h (F C_h F^T + W) E_h of every slot but the last is a variable, tied
        # by that equality (the covariance's own dynamics, explicit), and slot h + 1 builds on
        # its inverse. Eliminated, every tr(C_l) depends on all earlier slots through nested
        # inverses: a dense Hessian that took 53 % of a solve at M = 3 and most of the build;
        # lifted, each slot's terms couple its own UAVs with 16 numbers.
        lift = ca.SX.sym("lift", 16 * (L - 1))
        n_z, n_u = int(z.numel()), int(u.numel())
        stages: list[tuple[list[Any], LiftedSlot]] = []
        n_lift = int(lift.numel())
        ones4 = ca.SX.ones(4)
        lifted_rows: list[ca.SX] = []
        lifted_objective = ca.SX(0.0)
        objective = ca.SX(0.0)
        J_prior = j_pred
        J_prior_lifted = j_pred
        for h in range(L):
            x_l = ca.mtimes(ca.DM(np.linalg.matrix_power(F, h)), x_pred)
            J = J_prior
            J_info = ca.SX.zeros(4, 4)
            members = []
            for m in range(M):
                qm = q(h, m)
                em = eta[h * M + m]
                terms = information_terms(qm, em, x_l, self._sensing)
                J_info = J_info + terms
                i = 2 * (h * M + m)
                index = np.array([i, i + 1, n_z + n_u + h * M + m])
                members.append((index, ca.vertcat(z[i], z[i + 1], em), vech(terms)))
                limits = []
                if self.vehicle_model:
                    legs = (q(h - 1, m), v(h - 1, m), q(h, m), v(h, m), dt)
                    limits += [ca.sumsqr(acc) / s.a_max**2 for acc in end_accelerations(*legs)]
                    limits += [
                        ca.sumsqr(vc) / s.v_max**2 for vc in velocity_control_points(*legs)[1:]
                    ]
                # 14h also on the vehicle model: a vehicle faster than V_max now (the live
                # planner's V_max is 0.9 of the vehicles') would otherwise cover more than
                # V_max dt in its first slot.
                step2 = sq(qm - q(h - 1, m))
                bs = slice(2 * m, 2 * m + 2)
                add_uav_rows(rows, s, qm, em, serving[bs], control[bs], step2, e, S, limits)
                for frac in fracs:
                    p = motion.position_after(x_pred, (h - 1 + frac) * dt)
                    add_clearance_row(rows, along(h, m, frac) - p, (clearance[h] / S) ** 2, S)
                    for k in range(n_keep_out):
                        gap = along(h, m, frac) - keep_out[2 * k : 2 * k + 2]
                        add_clearance_row(rows, gap, keep2, S)
            for i in range(M):
                for j in range(i + 1, min(M, i + band + 1)):
                    for frac in fracs:
                        add_clearance_row(rows, along(h, i, frac) - along(h, j, frac), pair2, S)
            add(ca.sum1(eta[h * M : (h + 1) * M]), 1.0, 1.0)
            J = J + J_info
            dj, dp = scale_j[4 * h : 4 * h + 4], scale_p[4 * h : 4 * h + 4]
            C = scaled_inverse_sx(0.5 * (J + J.T), dj)
            objective = objective + weights[h] * ca.trace(C)
            Pt = ca.reshape(lift[16 * h : 16 * h + 16], 4, 4) if h + 1 < L else None
            slot = partial(lifted_slot, J_prior_lifted, dj, dp, Pt, weights[h], F, W)
            term, row = slot(J_info)
            stages.append((members, slot))
            lifted_objective = lifted_objective + term
            if h + 1 < L:
                assert row is not None and Pt is not None
                lifted_rows.append(row)
                P = ca.mtimes(ca.mtimes(ca.DM(F), C), ca.DM(F.T)) + ca.DM(W)
                J_prior = scaled_inverse_sx(0.5 * (P + P.T), dp)
                E = ca.diag(dp)
                Pt_inv = scaled_inverse_sx(0.5 * (Pt + Pt.T), ones4)
                J_prior_lifted = ca.mtimes(ca.mtimes(E, Pt_inv), E)

        # The terminal row (docs/model.md, "The terminal row"): at the end of the horizon,
        # |r| - |w|^2 / (2 a_max) >= c_L for the offset r from the predicted target and the
        # velocity w relative to it. Braking w at a_max keeps it, so the plan shifted by one
        # slot can be continued; without it the horizon ended where no next slot could keep the
        # clearance, and the shifted starts of the soak's tracking phase missed their rows.
        self.n_terminal = 0
        if self.vehicle_model and cfg.terminal_braking:
            target_end = motion.position_after(x_pred, (L - 1) * dt)
            brake = s.a_max * dt**2 / S  # in units of S per slot squared
            for m in range(M):
                offset = (q(L - 1, m) - target_end) / S
                relative = (v(L - 1, m) - x_pred[2:4]) * dt / S
                stopping = ca.sumsqr(relative) / (2 * brake)
                add(ca.norm_2(offset) - stopping - clearance[L - 1] / S, 0.0, float("inf"))
                self.n_terminal += 1
        x = ca.vertcat(z, u, eta)
        p = ca.vertcat(*params)
        self.n_x = int(x.numel())
        self.n_lift = n_lift
        self._lbg, self._ubg = rows.bounds()
        self._rate_rows = np.array(rows.rate_rows, dtype=int)
        g = ca.vertcat(*rows.rows)
        g_lifted = ca.vertcat(*lifted_rows)
        n_eq = int(g_lifted.numel())
        self._solver_lbg = np.concatenate([self._lbg, np.zeros(n_eq)])
        self._solver_ubg = np.concatenate([self._ubg, np.zeros(n_eq)])
        self.hess_lag = horizon_hess_lag(ca.vertcat(x, lift), p, g, lift, stages, f_scale)
        nlp = {
            "x": ca.vertcat(x, lift),
            "p": p,
            "f": lifted_objective / f_scale,
            "g": ca.vertcat(g, g_lifted),
        }
        opts: dict[str, Any] = {
            "print_time": False,
            "hess_lag": self.hess_lag,
            "ipopt": {**IPOPT_OPTIONS, "max_iter": cfg.max_iterations},
        }
        with lock:
            name = "horizon" if band == M - 1 else f"horizon_band{band}"
            self.solver: NlpSolver = ipopt(name, nlp, opts)
            warm_opts = {**opts, "ipopt": {**opts["ipopt"], **WARM_START_OPTIONS}}
            # The same NLP: the warm instance takes the cold one's derivative functions.
            self.warm_solver: NlpSolver = ipopt(f"{name}_warm", nlp, warm_opts, like=self.solver)
        self.lock: SolveLock = lock
        # For tests and the start point's scale: the weighted objective itself and its gradient.
        self.objective = ca.Function("f", [x, p], [objective])
        self.gradient = ca.Function("df", [x, p], [ca.gradient(objective, x)])
        self.constraints = ca.Function("g", [x, p], [g])
        # The lifted objective and equalities (the solver's, before the division by f_scale).
        self.lifted_problem = ca.Function(
            "lifted", [x, lift, p], [lifted_objective, g_lifted], ["x", "lift", "p"], ["f", "g"]
        )

    @property
    def lbg(self) -> FloatArray:
        return self._lbg

    @property
    def ubg(self) -> FloatArray:
        return self._ubg

    def _lower(self, data: HorizonSlotData) -> FloatArray:
        """The rows' lower bounds for the slot's R_th (nlp_model.lower_at_rate)."""
        return lower_at_rate(self._lbg, self._rate_rows, self.scenario.r_th, data.rate_min_bps)

    def pack(
        self,
        xy: FloatArray,
        velocity: FloatArray | None,
        eta: FloatArray,
        data: HorizonSlotData,
        f_scale: float = 1.0,
    ) -> tuple[FloatArray, FloatArray]:
        """(x, p) for a horizon plan xy [L, M, 2], velocity [L, M, 2] (vehicle model) and shares
        eta [L, M], with this slot's data."""
        z = (np.asarray(xy, dtype=float) - data.prev_xy[None]) / self.step_m
        parts = [z.reshape(-1)]
        if self.vehicle_model:
            if velocity is None:
                raise ValueError("the vehicle model needs planned velocities")
            parts.append(np.asarray(velocity, dtype=float).reshape(-1) / self.scenario.v_max)
        parts.append(np.asarray(eta, dtype=float).reshape(-1))
        x = np.concatenate(parts)
        values = [
            data.prev_xy,
            data.prev_velocity,
            data.serving_xy,
            data.control_xy,
            data.keep_out_xy,
            data.x_pred,
            np.asarray(data.J_pred, dtype=float).reshape(-1, order="F"),
            data.clearance_m,
            *self._along(np.asarray(xy, dtype=float), np.asarray(eta, dtype=float), data)[:2],
            np.array([f_scale]),
        ]
        p = np.concatenate([np.asarray(val, dtype=float).reshape(-1) for val in values])
        if len(p) != sum(self._param_sizes):
            raise ValueError(f"{len(p)} parameters, the NLP has {sum(self._param_sizes)}")
        return x, p

    def _along(
        self,
        xy: FloatArray,
        eta: FloatArray,
        data: HorizonSlotData,
        scales: tuple[FloatArray, FloatArray] | None = None,
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The bound's recursion along the plan (xy [L, M, 2], eta [L, M]): (scale_j [4 L],
        scale_p [4 L], lift [16 (L - 1)]). The scales are 1 / sqrt of the diagonals of J_l and
        of the next slot's predicted covariance P_l+1 (the last scale_p unused: ones), or the
        given ones; lift the lifted variables there in those scales, E_l P_l+1 E_l
        (l < L - 1), each column-major."""
        s = self.scenario
        along = bound_along(
            s.motion,
            s.dt,
            np.asarray(data.x_pred, dtype=float),
            np.asarray(data.J_pred, dtype=float),
            xy,
            eta,
            self._sensing,
        )
        L = self.length
        scale_j, scale_p = np.ones((L, 4)), np.ones((L, 4))
        if scales is not None:
            scale_j, scale_p = scales[0].reshape(L, 4), scales[1].reshape(L, 4)
        predicted = []
        for h in range(L):
            J = along.information[h]
            if scales is None:
                scale_j[h] = 1.0 / np.sqrt(np.maximum(np.diag(J), 1e-300))
            if h + 1 < L:
                P = along.next_covariance[h]
                if scales is None:
                    scale_p[h] = 1.0 / np.sqrt(np.diag(P))
                predicted.append(scale_p[h][:, None] * P * scale_p[h][None])
        lift = np.concatenate([m.reshape(-1, order="F") for m in predicted])
        return scale_j.reshape(-1), scale_p.reshape(-1), lift

    def lifted(
        self, xy: FloatArray, eta: FloatArray, data: HorizonSlotData, p: FloatArray
    ) -> FloatArray:
        """The lifted variables [16 (L - 1)] of the plan (xy [L, M, 2], eta [L, M]) in the
        scales of the parameters p (from `pack`)."""
        sizes = np.cumsum([0, *self._param_sizes])
        n_scale_j = len(self._param_sizes) - 3  # ..., scale_j, scale_p, f_scale
        scale_j = p[sizes[n_scale_j] : sizes[n_scale_j + 1]]
        scale_p = p[sizes[n_scale_j + 1] : sizes[n_scale_j + 2]]
        return self._along(xy, eta, data, (scale_j, scale_p))[2]

    def unpack(
        self, x: FloatArray, data: HorizonSlotData
    ) -> tuple[FloatArray, FloatArray | None, FloatArray]:
        """(xy [L, M, 2], velocity [L, M, 2] or None, eta [L, M]) of the NLP variables x."""
        s = self.scenario
        L, M = self.length, s.M
        n = L * M * 2
        xy = data.prev_xy[None] + self.step_m * np.asarray(x[:n]).reshape(L, M, 2)
        velocity = None
        if self.vehicle_model:
            velocity = s.v_max * np.asarray(x[n : 2 * n]).reshape(L, M, 2)
            n *= 2
        eta = np.asarray(x[n:], dtype=float).reshape(L, M)
        return xy, velocity, eta

    def bounds(self, data: HorizonSlotData) -> tuple[FloatArray, FloatArray]:
        """(lbx, ubx): the operating area on the positions, intersected with the box that 14h
        implies (|z_h| <= h + 1 per axis after h + 1 slots); velocities in the box |u| <= 1 that
        V_max implies; shares in [MIN_SHARE, 1]. The implied boxes change no solution; without
        them IPOPT took steps of kilometres in the acceleration phase and hit its cap on a
        fifth of the live slots."""
        from isac_mission.planning.feasibility import operating_area

        s = self.scenario
        L, M = self.length, s.M
        lo, hi = operating_area(s)
        reach = np.arange(1, L + 1, dtype=float)[:, None, None]  # [L, 1, 1], in V_max dt
        # Clipped to the reach box on both sides: a UAV more than a slot's reach outside the
        # area gets the point of the box nearest to the area (an empty box is an error to IPOPT;
        # the exact checks then refuse the answer's area miss, as any method's).
        lbz = np.clip((lo[None] - data.prev_xy) / self.step_m, -reach, reach).reshape(-1)
        ubz = np.clip((hi[None] - data.prev_xy) / self.step_m, -reach, reach).reshape(-1)
        n_u = L * M * 2 if self.vehicle_model else 0
        lbx = np.concatenate([lbz, np.full(n_u, -1.0), np.full(L * M, MIN_SHARE)])
        ubx = np.concatenate([ubz, np.full(n_u, 1.0), np.ones(L * M)])
        return lbx, ubx

    def violation(
        self,
        xy: FloatArray,
        velocity: FloatArray | None,
        eta: FloatArray,
        data: HorizonSlotData,
    ) -> float:
        """The largest amount by which the horizon plan (xy [L, M, 2], velocity, eta [L, M])
        misses a constraint or bound of the NLP (scaled units; 0 if it meets them all)."""
        x, p = self.pack(xy, velocity, eta, data)
        g = np.asarray(self.constraints(x, p), dtype=float).ravel()
        lbx, ubx = self.bounds(data)
        misses = np.concatenate([self._lower(data) - g, g - self._ubg, lbx - x, x - ubx])
        return float(np.max(misses, initial=0.0))

    def satisfies(
        self,
        xy: FloatArray,
        velocity: FloatArray | None,
        eta: FloatArray,
        data: HorizonSlotData,
        tol: float = 1e-9,
    ) -> bool:
        """True if the horizon plan (xy [L, M, 2], velocity, eta [L, M]) meets every constraint
        and bound of the NLP (scaled units, slack tol)."""
        return self.violation(xy, velocity, eta, data) <= tol

    def warm_duals(
        self, duals: HorizonDuals, f_scale: float
    ) -> tuple[FloatArray, FloatArray] | None:
        """(lam_x0, lam_g0): last slot's multipliers `duals` shifted by one slot, as its plan is
        (each horizon slot's block takes the next one's, the last repeats), in the units of an
        objective divided by f_scale; None if they are of another problem (another band or
        size)."""
        L = self.length
        n_rows = len(self._lbg)
        if (
            duals.pair_band != self.pair_band
            or len(duals.lam_x) != self.n_x + self.n_lift
            or len(duals.lam_g) != n_rows + self.n_lift
        ):
            return None
        # x is z, u (vehicle model) and eta, each L blocks of one horizon slot, then the L - 1
        # lifted covariances; the rows are L blocks of one slot, the terminal rows, then the
        # lifted equalities.
        lam_x = np.concatenate(
            [
                *(_shift_slots(duals.lam_x[i : i + L * w], L) for i, w in self._slot_blocks()),
                _shift_slots(duals.lam_x[self.n_x :], L - 1),
            ]
        )
        n_slot_rows = n_rows - self.n_terminal
        lam_g = np.concatenate(
            [
                _shift_slots(duals.lam_g[:n_slot_rows], L),
                duals.lam_g[n_slot_rows:n_rows],
                _shift_slots(duals.lam_g[n_rows:], L - 1),
            ]
        )
        ratio = duals.f_scale / f_scale
        return ratio * lam_x, ratio * lam_g

    def _slot_blocks(self) -> list[tuple[int, int]]:
        """(offset, width per horizon slot) of z, u (vehicle model) and eta in x."""
        M, L = self.scenario.M, self.length
        widths = [2 * M] + ([2 * M] if self.vehicle_model else []) + [M]
        offsets = np.cumsum([0, *(L * w for w in widths)])[:-1]
        return [(int(o), w) for o, w in zip(offsets, widths, strict=True)]

    def solve(
        self,
        xy0: FloatArray,
        velocity0: FloatArray | None,
        eta0: FloatArray,
        data: HorizonSlotData,
        duals: HorizonDuals | None = None,
    ) -> HorizonSolution:
        """Solve from the start (xy0 [L, M, 2], velocity0, eta0 [L, M]); duals: last slot's
        multipliers when the start is its plan shifted (`warm_duals`), else a cold start."""
        x0, p = self.pack(xy0, velocity0, eta0, data)
        f0 = float(self.objective(x0, p))
        f_scale = f0 if np.isfinite(f0) and f0 > 0 else 1.0
        x0, p = self.pack(xy0, velocity0, eta0, data, f_scale)
        lbx, ubx = self.bounds(data)
        x0 = np.clip(x0, lbx, ubx)
        xy0, _, eta0 = self.unpack(x0, data)
        lift0 = self.lifted(xy0, eta0, data, p)
        free = np.full(self.n_lift, np.inf)
        warm = None if duals is None else self.warm_duals(duals, f_scale)
        solver, multipliers = self.solver, {}
        if warm is not None:
            solver, multipliers = self.warm_solver, {"lam_x0": warm[0], "lam_g0": warm[1]}
        with self.lock:
            sol = solver(
                x0=np.concatenate([x0, lift0]),
                p=p,
                lbx=np.concatenate([lbx, -free]),
                ubx=np.concatenate([ubx, free]),
                lbg=np.concatenate([self._lower(data), self._solver_lbg[len(self._lbg) :]]),
                ubg=self._solver_ubg,
                **multipliers,
            )
            stats = solver.stats()
        x_opt = np.asarray(sol["x"], dtype=float).ravel()[: self.n_x]
        xy, velocity, eta = self.unpack(x_opt, data)
        eta = np.maximum(eta, 0.0)
        eta = eta / eta.sum(axis=1, keepdims=True)
        return HorizonSolution(
            uav_xy_m=xy,
            uav_velocity_mps=velocity,
            bandwidth_share=eta,
            status=str(stats.get("return_status", "unknown")),
            success=bool(stats.get("success", False)),
            iterations=int(stats.get("iter_count", 0)),
            lam_x=np.asarray(sol["lam_x"], dtype=float).ravel(),
            lam_g=np.asarray(sol["lam_g"], dtype=float).ravel(),
            f_scale=f_scale,
        )


def _shift_slots(values: FloatArray, n_slots: int) -> FloatArray:
    """values [n_slots * k], k per horizon slot, shifted by one slot: slot l takes slot l + 1's,
    the last keeps its own."""
    values = np.asarray(values, dtype=float)
    if n_slots <= 1:  # one slot (or none: the lifted blocks of a horizon of one) keeps its own
        return values
    blocks = values.reshape(n_slots, -1)
    return np.concatenate([blocks[1:], blocks[-1:]]).reshape(-1)
