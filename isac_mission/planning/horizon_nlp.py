"""The receding-horizon NLP as a solver: IPOPT around the symbolic problem, a slot's numbers in
and its plan out.

The problem itself (variables, objective, rows, their bounds: CasADi expressions of the
scenario, built once) is planning/horizon_problem.py. Here, per slot: the plan and the slot's
data (HorizonSlotData) packed into the NLP's scaled variables and parameters (`pack`, `lifted`;
positions in units of S = V_max dt from where the UAVs are, velocities in units of V_max, the
Jacobi scalings taken at the start point) and back (`unpack`), the variables' bounds
(`bounds`), the objective's scale and the start clipped into the bounds, last slot's
multipliers shifted as a warm start (`warm_duals`), and IPOPT's call under the solve lock
(`solve`). `violation` and `satisfies` evaluate the rows and bounds at a plan.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, replace
from typing import Any

import casadi as ca
import numpy as np

from isac_mission.config import Scenario
from isac_mission.planning.feasibility import operating_area
from isac_mission.planning.horizon_problem import HorizonProblem, build_horizon_problem
from isac_mission.planning.margins import MIN_SHARE
from isac_mission.planning.nlp_model import (
    IpoptFactory,
    NlpSolver,
    SolveLock,
    lower_at_rate,
    plain_ipopt,
)
from isac_mission.tracking.pcrb import SensingParams, bound_along
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
    # iteration instead of 34 (docs/decisions/0016-horizon-kkt-unscaled.md).
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


@dataclass(frozen=True)
class HorizonSlotData:
    """One slot's parameters of the horizon NLP.

    prev_xy [M, 2] (m), prev_velocity [M, 2] (m/s; zeros for the paper's kinematics);
    serving_xy, control_xy [M, 2]: the serving BS (14a) and the control BS (14b) per UAV;
    keep_out_xy [n_keep_out, 2]; x_pred [4]: slot n's predicted target state (m, m/s); J_pred
    [4, 4]: its prior information; clearance_m [L]: the 14j distance (m) per horizon slot;
    rate_min_bps: R_th (bit/s), the planning scenario's (an operator may change it; the NLP
    takes it as a bound: `_lower`). For T > 1 targets (in the NLP's order of targets): x_pred
    [T, 4], J_pred [T, 4, 4], clearance_m [T, L] and target_weight [T] (each target's weight in
    the objective); one target has no weight (None). path_offset [T, L, 4] (m, m/s) or None
    (zeros): each target's predicted state at the end of horizon slot h minus the straight
    F^h x_pred (`TargetBelief.path_offsets`).
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
    target_weight: FloatArray | None = None
    path_offset: FloatArray | None = None

    @property
    def n_targets(self) -> int:
        """T, the targets the data is for (1: x_pred [4])."""
        x = np.asarray(self.x_pred)
        return 1 if x.ndim == 1 else int(x.shape[0])

    def states(self) -> FloatArray:
        """Every target's predicted state [T, 4] (m, m/s)."""
        return np.asarray(self.x_pred, dtype=float).reshape(-1, 4)

    def offsets(self, length: int) -> FloatArray:
        """Every target's path offsets [T, length, 4] (m, m/s; zeros without any)."""
        if self.path_offset is None:
            return np.zeros((self.n_targets, length, 4))
        return np.asarray(self.path_offset, dtype=float).reshape(self.n_targets, length, 4)

    def priors(self) -> FloatArray:
        """Every target's prior information [T, 4, 4]."""
        return np.asarray(self.J_pred, dtype=float).reshape(-1, 4, 4)

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
    """The horizon problem for the scenario's M UAVs and n_keep_out keep-out points, as a solver:
    the symbolic problem (planning/horizon_problem.py) with IPOPT around it, and a slot's numbers
    (HorizonSlotData, a plan [L, M, 2] of positions in m and velocities in m/s, shares [L, M])
    packed into its variables and parameters, its bounds, its start and warm start, its answer
    unpacked."""

    def __init__(
        self,
        scenario: Scenario,
        n_keep_out: int = 0,
        lock: SolveLock | None = None,
        ipopt: IpoptFactory = plain_ipopt,
        pair_band: int | None = None,
        n_targets: int = 1,
    ) -> None:
        """lock: held around IPOPT's construction and every solve (SolverKit.solve_lock); ipopt:
        what builds the solver (SolverKit.ipopt); pair_band: the UAV-UAV rows only of the UAV
        slots a < b with b - a <= pair_band (planning/pairs.py; the caller orders the fleet so
        that every pair within reach is among them), None: every pair; n_targets: the targets T
        it plans for (horizon_problem.build_horizon_problem)."""
        problem = build_horizon_problem(scenario, n_keep_out, pair_band, n_targets)
        self.problem = problem
        self.scenario = scenario
        self.n_keep_out = n_keep_out
        self.n_targets = n_targets
        self.pair_band = problem.pair_band
        self.length = problem.length
        self.vehicle_model = problem.vehicle_model
        self.step_m = problem.step_m
        self.margins = problem.margins
        self.pair_clearance_m = problem.pair_clearance_m
        """The distance the UAV-UAV rows keep at each leg sample, m."""
        self.n_terminal = problem.n_terminal
        self.n_x = problem.n_x
        self.n_lift = problem.n_lift
        self.hess_lag = problem.hess_lag
        self._sensing = SensingParams.from_scenario(scenario)
        self._param_sizes = problem.param_sizes
        self._lbg, self._ubg = problem.lbg, problem.ubg
        self._rate_rows = problem.rate_rows
        n_eq = int(problem.g_lifted.numel())
        self._solver_lbg = np.concatenate([self._lbg, np.zeros(n_eq)])
        self._solver_ubg = np.concatenate([self._ubg, np.zeros(n_eq)])
        self.lock: SolveLock = lock if lock is not None else contextlib.nullcontext()
        self.solver, self.warm_solver = _ipopt_solvers(problem, scenario, self.lock, ipopt)
        x, lift, p = problem.x, problem.lift, problem.p
        # For tests and the start point's scale: the weighted objective itself and its gradient.
        self.objective = ca.Function("f", [x, p], [problem.objective])
        self.gradient = ca.Function("df", [x, p], [ca.gradient(problem.objective, x)])
        self.constraints = ca.Function("g", [x, p], [problem.g])
        # The lifted objective and equalities (the solver's, before the division by f_scale).
        self.lifted_problem = ca.Function(
            "lifted",
            [x, lift, p],
            [problem.lifted_objective, problem.g_lifted],
            ["x", "lift", "p"],
            ["f", "g"],
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
        if data.n_targets != self.n_targets:
            raise ValueError(f"data of {data.n_targets} targets, the NLP has {self.n_targets}")
        weight = []
        if self.n_targets > 1:
            if data.target_weight is None:
                raise ValueError("several targets need their weights")
            weight = [np.asarray(data.target_weight, dtype=float)]
        values = [
            data.prev_xy,
            data.prev_velocity,
            data.serving_xy,
            data.control_xy,
            data.keep_out_xy,
            data.x_pred,
            np.concatenate([J.reshape(-1, order="F") for J in data.priors()]),
            data.clearance_m,
            *weight,
            data.offsets(self.length),
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
        """The bound's recursion of every target along the plan (xy [L, M, 2], eta [L, M]):
        (scale_j [4 L T], scale_p [4 L T], lift [16 (L - 1) T]), target-major (`_along_one`)."""
        T, L = data.n_targets, self.length
        states, priors, offsets = data.states(), data.priors(), data.offsets(L)
        parts = []
        for i in range(T):
            one_scales = None
            if scales is not None:
                one_scales = (
                    scales[0][4 * L * i : 4 * L * (i + 1)],
                    scales[1][4 * L * i : 4 * L * (i + 1)],
                )
            parts.append(self._along_one(xy, eta, states[i], priors[i], one_scales, offsets[i]))
        if T == 1:
            return parts[0]
        return (
            np.concatenate([part[0] for part in parts]),
            np.concatenate([part[1] for part in parts]),
            np.concatenate([part[2] for part in parts]),
        )

    def _along_one(
        self,
        xy: FloatArray,
        eta: FloatArray,
        x_pred: FloatArray,
        J_pred: FloatArray,
        scales: tuple[FloatArray, FloatArray] | None = None,
        offsets: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """One target's (x_pred [4], J_pred [4, 4], path offsets [L, 4] or None) bound
        recursion along the plan (xy
        [L, M, 2], eta [L, M]): (scale_j [4 L], scale_p [4 L], lift [16 (L - 1)]). The scales are
        1 / sqrt of the diagonals of J_l and of the next slot's predicted covariance P_l+1 (the
        last scale_p unused: ones), or the given ones; lift the lifted variables there in those
        scales, E_l P_l+1 E_l (l < L - 1), each column-major."""
        s = self.scenario
        along = bound_along(
            s.motion,
            s.dt,
            np.asarray(x_pred, dtype=float),
            np.asarray(J_pred, dtype=float),
            xy,
            eta,
            self._sensing,
            offsets,
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
        L, T = self.length, self.n_targets
        n_rows = len(self._lbg)
        # The lifted blocks are 16 (L - 1) per target: a changed target count changes the sizes
        # (a cold start then).
        if (
            duals.pair_band != self.pair_band
            or len(duals.lam_x) != self.n_x + self.n_lift
            or len(duals.lam_g) != n_rows + self.n_lift
        ):
            return None
        # x is z, u (vehicle model) and eta, each L blocks of one horizon slot, then each
        # target's L - 1 lifted covariances; the rows are L blocks of one slot, the terminal
        # rows, then each target's lifted equalities.
        lam_x = np.concatenate(
            [
                *(_shift_slots(duals.lam_x[i : i + L * w], L) for i, w in self._slot_blocks()),
                *(_shift_slots(lam, L - 1) for lam in np.split(duals.lam_x[self.n_x :], T)),
            ]
        )
        n_slot_rows = n_rows - self.n_terminal
        lam_g = np.concatenate(
            [
                _shift_slots(duals.lam_g[:n_slot_rows], L),
                duals.lam_g[n_slot_rows:n_rows],
                *(_shift_slots(lam, L - 1) for lam in np.split(duals.lam_g[n_rows:], T)),
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

    def start_point(
        self,
        xy0: FloatArray,
        velocity0: FloatArray | None,
        eta0: FloatArray,
        data: HorizonSlotData,
    ) -> StartPoint:
        """The start (xy0 [L, M, 2] m, velocity0 [L, M, 2] m/s or None, eta0 [L, M]) as IPOPT
        takes it: the objective's scale f_scale (its value there, 1 if not finite and positive),
        the parameters packed with it, the variables clipped into their bounds, and the lifted
        variables of the clipped plan."""
        x0, p = self.pack(xy0, velocity0, eta0, data)
        f0 = float(self.objective(x0, p))
        f_scale = f0 if np.isfinite(f0) and f0 > 0 else 1.0
        x0, p = self.pack(xy0, velocity0, eta0, data, f_scale)
        lbx, ubx = self.bounds(data)
        x0 = np.clip(x0, lbx, ubx)
        xy0, _, eta0 = self.unpack(x0, data)
        lift0 = self.lifted(xy0, eta0, data, p)
        return StartPoint(x0, lift0, p, lbx, ubx, f_scale)

    def _run(
        self,
        start: StartPoint,
        data: HorizonSlotData,
        warm: tuple[FloatArray, FloatArray] | None,
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """IPOPT's answer and stats from `start` (the lifted variables free, the rows' lower
        bounds at the slot's R_th, the lifted equalities = 0): the cold solver, or with warm
        (lam_x0 [n_x + n_lift], lam_g0 [n_rows + n_lift]) the warm-start one."""
        free = np.full(self.n_lift, np.inf)
        solver, multipliers = self.solver, {}
        if warm is not None:
            solver, multipliers = self.warm_solver, {"lam_x0": warm[0], "lam_g0": warm[1]}
        with self.lock:
            sol = solver(
                x0=np.concatenate([start.x0, start.lift0]),
                p=start.p,
                lbx=np.concatenate([start.lbx, -free]),
                ubx=np.concatenate([start.ubx, free]),
                lbg=np.concatenate([self._lower(data), self._solver_lbg[len(self._lbg) :]]),
                ubg=self._solver_ubg,
                **multipliers,
            )
            stats = solver.stats()
        return sol, stats

    def _solution(
        self, sol: dict[str, Any], stats: dict[str, Any], data: HorizonSlotData, f_scale: float
    ) -> HorizonSolution:
        """IPOPT's answer `sol` unpacked (shares clipped at 0, each slot's renormalised to sum
        1), with its status from `stats` and its multipliers."""
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
        start = self.start_point(xy0, velocity0, eta0, data)
        warm = None if duals is None else self.warm_duals(duals, start.f_scale)
        sol, stats = self._run(start, data, warm)
        return self._solution(sol, stats, data, start.f_scale)


@dataclass(frozen=True)
class StartPoint:
    """A start as IPOPT takes it (HorizonNLP.start_point): x0 [n_x] (scaled, within the bounds
    lbx, ubx [n_x]), lift0 [n_lift], the parameters p packed with f_scale, the objective's
    divisor."""

    x0: FloatArray
    lift0: FloatArray
    p: FloatArray
    lbx: FloatArray
    ubx: FloatArray
    f_scale: float


def _ipopt_solvers(
    problem: HorizonProblem, s: Scenario, lock: SolveLock, ipopt: IpoptFactory
) -> tuple[NlpSolver, NlpSolver]:
    """The cold and the warm-start IPOPT solvers of `problem` (built under lock; the warm one
    takes the cold one's derivative functions), named "horizon" (every pair) or
    "horizon_band<b>", with "_targets<T>" for T > 1 targets."""
    opts: dict[str, Any] = {
        "print_time": False,
        "hess_lag": problem.hess_lag,
        "ipopt": {**IPOPT_OPTIONS, "max_iter": s.planner.horizon.max_iterations},
    }
    band = problem.pair_band
    with lock:
        name = "horizon" if band == s.M - 1 else f"horizon_band{band}"
        if problem.n_targets > 1:
            name += f"_targets{problem.n_targets}"
        solver = ipopt(name, problem.nlp, opts)
        warm_opts = {**opts, "ipopt": {**opts["ipopt"], **WARM_START_OPTIONS}}
        # The same NLP: the warm instance takes the cold one's derivative functions.
        warm_solver = ipopt(f"{name}_warm", problem.nlp, warm_opts, like=solver)
    return solver, warm_solver


def _shift_slots(values: FloatArray, n_slots: int) -> FloatArray:
    """values [n_slots * k], k per horizon slot, shifted by one slot: slot l takes slot l + 1's,
    the last keeps its own."""
    values = np.asarray(values, dtype=float)
    if n_slots <= 1:  # one slot (or none: the lifted blocks of a horizon of one) keeps its own
        return values
    blocks = values.reshape(n_slots, -1)
    return np.concatenate([blocks[1:], blocks[-1:]]).reshape(-1)
