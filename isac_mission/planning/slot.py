"""plan_slot(): one slot of the planner (Algorithm 2) and the benchmark strategies.

One pure function per slot: (scenario via the kit, previous plan, predicted track, prior
information) -> plan. No clock state, no RNG, no I/O: the offline simulation and the live service
call the same function. The strategies share it:

- proposed: positions by Algorithm 1 and shares by (P1.2.1), alternated (Algorithm 2), with,
  when planner.polish is set, the exact problem polished (planning/polish.py) after the first AO
  iteration (kept if it gains more than epsilon there, else Algorithm 2 resumes and is polished
  at its end), then from the best other leader of the band (planning/basins.py);
- proposed-sca: Algorithm 2 alone, never polished (the paper's algorithm as printed);
- sd: static deployment, UAVs stay where they are, shares optimised;
- aba: average bandwidth (eta = 1/M), positions by Algorithm 1;
- crb: the proposed optimiser with the measurement-only objective tr(J_M^-1);
- comm: the communication-optimal plan of Section III-A;
- horizon: slots n..n+L-1 planned together on the bound's recursion (planning/horizon.py), the
  first flown; the polished per-slot plan is its start and its fallback.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.vehicle import VehicleModel
from isac_mission.planning.association import AssociationLP, associate
from isac_mission.planning.bandwidth import BandwidthSubproblem, optimise_shares
from isac_mission.planning.basins import screen_leaders
from isac_mission.planning.communication import communication_optimal, lemma1_shares
from isac_mission.planning.feasibility import SlotConstraints, capacity_ok, operating_area
from isac_mission.planning.horizon import plan_horizon
from isac_mission.planning.horizon_nlp import HorizonNLP
from isac_mission.planning.nlp_rows import SolveLock
from isac_mission.planning.polish import PolishNLP
from isac_mission.planning.positions import PositionSubproblem, optimise_positions
from isac_mission.planning.safety import target_clearance_m
from isac_mission.tracking.pcrb import PlanningObjective, SensingParams, scaled_inverse
from isac_mission.types import FloatArray, IntArray, SlotPlan, SolveReport

EARLY_POLISH_GAIN = 1e-6
"""The early polish (after AO iteration 1) is kept only if it lowers tr(PCRB) by more than this
(relative) there: a smaller gain means Algorithm 2 had nearly converged, and its end point (which
the polish may then match only to IPOPT's tolerance) is polished instead."""

Method = Literal["proposed", "proposed-sca", "sd", "aba", "crb", "comm", "horizon"]
METHODS: tuple[Method, ...] = ("proposed", "proposed-sca", "sd", "aba", "crb", "comm", "horizon")


@dataclass(frozen=True)
class SlotInput:
    """What the planner knows at the start of slot n.

    prev_xy [M, 2]: where the UAVs are (q_{n-1}); prev_eta [M]: last slot's shares;
    prev_assoc [M] or None: last slot's BS per UAV; x_pred [4]: predicted target state;
    J_pred [4, 4]: prior information of the bound at this slot; prev_velocity [M, 2] or None:
    the vehicles' velocities now (used when planner.accel_limit_mps2 or planner.vehicle_model
    is set); keep_out_xy [L, 2] or None: vehicles outside this plan that every planned UAV keeps
    D_s from (the kit must be built with n_keep_out = L); target_cov_pred [4, 4] or None: the
    tracker's predicted covariance of the target (the safety rule; None: J_pred^-1);
    prev_plan: last slot's plan (the horizon's warm start), None at the first slot.
    """

    prev_xy: FloatArray
    prev_eta: FloatArray
    prev_assoc: IntArray | None
    x_pred: FloatArray
    J_pred: FloatArray
    prev_velocity: FloatArray | None = None
    keep_out_xy: FloatArray | None = None
    target_cov_pred: FloatArray | None = None
    prev_plan: SlotPlan | None = None


class SolverKit:
    """The convex problems of one scenario, built once (DPP) and re-solved every slot."""

    def __init__(
        self,
        scenario: Scenario,
        fast: bool = True,
        n_keep_out: int = 0,
        solve_lock: SolveLock | None = None,
    ) -> None:
        """fast=False is the reference path (the planner before docs/performance.md): (P1.1.2)
        through cvxpy instead of a direct Clarabel call, (P1.2.1) by the cvxpy LP instead of its
        closed-form vertex, the association LP every slot, and the per-UAV line search on full
        batches. Both paths solve the same problems; they differ by solver tolerance.
        n_keep_out: the number of keep-out points (SlotInput.keep_out_xy) each slot carries.
        solve_lock: held around every IPOPT construction and solve (planning/nlp_rows.SolveLock;
        the live service shares one threading lock between its kits); None: a null context."""
        s = scenario
        self.scenario = s
        self.fast = fast
        self.n_keep_out = n_keep_out
        self.sensing = SensingParams.from_scenario(s)
        self.positions = PositionSubproblem(s, s.planner.solver, direct=fast, n_keep_out=n_keep_out)
        self.shares = BandwidthSubproblem(s.M, "closed-form" if fast else "HIGHS")
        self.association = AssociationLP(s.M, s.K, s.n_a, shortcut=fast)
        self.solve_lock: SolveLock = (
            solve_lock if solve_lock is not None else contextlib.nullcontext()
        )
        self._polish: PolishNLP | None = None
        self._horizon: HorizonNLP | None = None

    @property
    def polish(self) -> PolishNLP:
        """The exact slot problem (planning/polish.py), built on first use and kept."""
        if self._polish is None:
            s = self.scenario
            self._polish = PolishNLP(
                s, self.n_keep_out, s.planner.polish_max_iterations, self.solve_lock
            )
        return self._polish

    def renewed(self) -> SolverKit:
        """A kit with fresh convex problems (their cvxpy Parameters are per-kit state, which a
        timed-out plan's thread may still be writing) sharing this kit's IPOPT problems (built
        once: their solves are serialised by solve_lock). A horizon kit rebuilt after every
        timeout spent its next plan's budget on the build, and the timeouts cascaded."""
        kit = SolverKit(
            self.scenario, fast=self.fast, n_keep_out=self.n_keep_out, solve_lock=self.solve_lock
        )
        kit._polish, kit._horizon = self._polish, self._horizon
        return kit

    @property
    def horizon(self) -> HorizonNLP:
        """The receding-horizon NLP (planning/horizon_nlp.py), built on first use and kept."""
        if self._horizon is None:
            self._horizon = HorizonNLP(self.scenario, self.n_keep_out, self.solve_lock)
        return self._horizon

    def warm_up(self, method: Method = "proposed") -> None:
        """Solve every problem once so that the first real slot does not pay for compilation."""
        s = self.scenario
        plan_slot(
            SlotInput(
                prev_xy=s.uav_start_xy,
                prev_eta=np.full(s.M, 1.0 / s.M),
                prev_assoc=None,
                x_pred=s.x0,
                J_pred=np.asarray(np.linalg.inv(s.P0), dtype=float),
                # Far outside the area: present for the solver's shape, never binding.
                keep_out_xy=np.full((self.n_keep_out, 2), -1e6) if self.n_keep_out else None,
            ),
            self,
            method,
        )


def _plan(
    xy: FloatArray,
    assoc: IntArray,
    eta: FloatArray,
    objective: PlanningObjective,
    report: SolveReport,
) -> SlotPlan:
    full = PlanningObjective(objective.J_pred, objective.x_pred, objective.sensing)
    return SlotPlan(
        uav_xy_m=xy,
        bs_of_uav=assoc,
        bandwidth_share=eta,
        pcrb_trace=full.value(xy, eta),
        report=report,
    )


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


def slot_clearance_m(inp: SlotInput, s: Scenario) -> float:
    """The slot's 14j clearance (planning/safety.py) from the tracker's predicted covariance,
    or J_pred^-1 when the input has none."""
    cov = inp.target_cov_pred
    if cov is None and s.planner.safety_margin != "none":
        cov = np.asarray(np.linalg.inv(inp.J_pred), dtype=float)
    return target_clearance_m(s, cov)


def plan_slot(inp: SlotInput, kit: SolverKit, method: Method = "proposed") -> SlotPlan:
    """Plan one slot with the given strategy. An infeasible slot returns a best-effort plan (the
    communication-optimal one, or staying put for sd) with report.status == "infeasible".

    With planner.vehicle_model the waypoints keep within the exact reach a_max dt^2 / 4 of the
    coasting point (model/vehicle.py) and the plan carries the mean-velocity leg's end velocity
    (q_n - q_{n-1}) / dt as uav_velocity_mps (docs/model.md, "Vehicle model")."""
    plan = _plan_slot(inp, kit, method)
    if kit.scenario.planner.vehicle_model and plan.uav_velocity_mps is None:
        end_v = VehicleModel.of(kit.scenario).end_velocity(inp.prev_xy, plan.uav_xy_m)
        plan = dataclasses.replace(plan, uav_velocity_mps=end_v)
    return plan


def _plan_slot(inp: SlotInput, kit: SolverKit, method: Method) -> SlotPlan:
    t0 = time.perf_counter()
    if method == "horizon":
        base = plan_slot(inp, kit, "proposed")
        cov = inp.target_cov_pred
        return plan_horizon(
            inp.prev_xy,
            inp.prev_velocity,
            inp.keep_out_xy,
            inp.x_pred,
            inp.J_pred,
            scaled_inverse(inp.J_pred) if cov is None else cov,
            inp.prev_plan,
            base,
            kit.horizon,
            kit.sensing,
            t0,
        )
    s = kit.scenario
    cfg = s.planner
    n_keep_out = 0 if inp.keep_out_xy is None else len(inp.keep_out_xy)
    if n_keep_out != kit.n_keep_out:
        raise ValueError(f"{n_keep_out} keep-out points, but the kit is built for {kit.n_keep_out}")
    if cfg.association == "keep" and inp.prev_assoc is not None:
        assoc = inp.prev_assoc
    else:
        assoc = associate(
            inp.prev_xy, s.bs_xy, capacity=s.n_a, dH=s.dH, rho0=s.rho0, B=s.B, lp=kit.association
        )
    serving = s.bs_xy[assoc]
    ballistic = None
    reach_m = VehicleModel.of(s).reach_radius_m if cfg.vehicle_model else np.inf
    if not cfg.vehicle_model and cfg.accel_limit_mps2 is not None:
        reach_m = cfg.accel_limit_mps2 * s.dt**2 / 4
    if np.isfinite(reach_m) and inp.prev_velocity is not None:
        # Where the vehicles coast to, pulled inside the 14h disk: a vehicle a little faster than
        # the planner's V_max has to slow down anyway.
        coast = inp.prev_velocity * s.dt
        norm = np.linalg.norm(coast, axis=1, keepdims=True)
        coast = coast * np.minimum(1.0, s.v_max * s.dt * (1 - 1e-9) / np.maximum(norm, 1e-12))
        # ... and inside the operating area: a vehicle heading out at the edge must stop too.
        ballistic = np.clip(inp.prev_xy + coast, *operating_area(s))
    cons = SlotConstraints(
        inp.prev_xy,
        serving,
        s.bs_xy,
        inp.x_pred[:2],
        s,
        ballistic_xy=ballistic,
        accel_radius_m=reach_m if ballistic is not None else np.inf,
        keep_out_xy=inp.keep_out_xy if n_keep_out else None,
        target_clearance_m=slot_clearance_m(inp, s),
        target_velocity_mps=inp.x_pred[2:4],
        start_velocity_mps=inp.prev_velocity,
    )
    moves = method not in ("sd",)
    step = s.v_max * s.dt if moves else 0.0
    comm = communication_optimal(inp.prev_xy, serving, max_step_m=step, dH=s.dH, rho0=s.rho0, B=s.B)
    objective = PlanningObjective(
        inp.J_pred, inp.x_pred, kit.sensing, measurement_only=(method == "crb")
    )

    def elapsed() -> float:
        return time.perf_counter() - t0

    def fallback(reason: str) -> SlotPlan:
        # Best effort: the link-optimal waypoints, or where the vehicles coast to when the
        # planner respects their dynamics; either way away from the target first.
        best = comm.uav_xy if ballistic is None else ballistic
        xy = evade_target(best, inp.prev_xy, inp.x_pred[:2], cons.clearance_m, step)
        xy = np.clip(xy, *cons.area_bounds())  # the vehicles' geofence would clamp it anyway
        report = SolveReport("infeasible", reason, solve_s=elapsed(), fallback="infeasible")
        return _plan(xy, assoc, comm.eta, objective, report)

    if comm.worst_rate_bps < s.r_th:
        return fallback(
            f"infeasible: communication-optimal worst rate R_c* = {comm.worst_rate_bps / 1e6:.3f} "
            f"Mbit/s < R_th = {s.r_th / 1e6:.3f} Mbit/s"
        )
    if method == "comm":
        violated = cons.describe_violations(comm.uav_xy, comm.eta)
        status = "ok" if not violated else "infeasible"
        return _plan(
            comm.uav_xy,
            assoc,
            comm.eta,
            objective,
            SolveReport(status, ", ".join(violated), solve_s=elapsed()),
        )

    # Start where the vehicles can be: with a dynamics limit, where they coast to.
    Q = inp.prev_xy if ballistic is None or not moves else ballistic
    if method == "aba":
        eta = np.full(s.M, 1.0 / s.M)
    else:
        eta = inp.prev_eta
        if bool(cons.rate_violations(Q[None], eta[None])[0]):
            eta = lemma1_shares(cons.full_rates(Q))
    f = objective.value(Q, eta)
    history = [f]
    n_pos = n_bw = n_ao = 0
    search = {"epsilon": cfg.epsilon, "step": cfg.line_search_step}
    note, reason, n_polish = "", "", 0
    polish = method == "proposed" and cfg.polish and moves
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
        if method != "aba":
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
        if polish and ao_iteration == 1 and decrease > cfg.epsilon:
            # The polish after the first AO iteration (docs/model.md, "The polish"): kept when
            # it gains more than EARLY_POLISH_GAIN on that point; otherwise Algorithm 2 resumes.
            early = kit.polish.polish(Q, eta, objective, cons)
            if early.accepted and f_new - early.value > EARLY_POLISH_GAIN * f_new:
                Q, eta, polished_early = early.uav_xy_m, early.bandwidth_share, True
                note, n_polish = f"{early.note} after AO iteration 1", early.iterations
                history.append(early.value)
                break
            n_early = early.iterations
        if decrease <= cfg.epsilon or not (moves and method != "aba"):
            break
    violated = cons.describe_violations(Q, eta)
    if not capacity_ok(assoc, s.K, s.n_a):
        violated.append("14e capacity")
    if violated:
        return fallback("infeasible: no plan satisfies " + ", ".join(violated))
    if polish and not polished_early:
        polished = kit.polish.polish(Q, eta, objective, cons)
        note, n_polish = polished.note, n_early + polished.iterations
        if polished.accepted:
            Q, eta = polished.uav_xy_m, polished.bandwidth_share
            history.append(polished.value)
        else:
            reason = polished.note
    if polish:
        # The other basins: the band's leader moved to another UAV (planning/basins.py).
        f_best = history[-1]
        for leader, start_eta in screen_leaders(Q, eta, objective, f_best):
            other = kit.polish.polish(Q, start_eta, objective, cons)
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
        solve_s=elapsed(),
        objective_history=tuple(float(v) for v in history),
        polish=note,
        polish_iterations=n_polish,
    )
    return _plan(Q, assoc, eta, objective, report)
