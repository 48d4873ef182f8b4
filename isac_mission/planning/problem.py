"""The slot problem: what every planning method needs, built once from the slot's input.

`build_slot_problem` turns a `SlotInput` (what the planner knows at the start of slot n) and the
scenario's kit into a `SlotProblem`: the association, the reach of each vehicle (the coasting
point and the acceleration disk), the exact constraint set with its clearances and margins
(planning/feasibility.py, planning/margins.py), the communication-optimal plan of Section III-A
and the objective. The methods (planning/registry.py) differ only in what they do with it.
Pure: no clock but the plan's own timer, no RNG, no I/O.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.config import Scenario
from isac_mission.deprecation import renamed_fields
from isac_mission.model.vehicle import VehicleModel
from isac_mission.planning.association import associate
from isac_mission.planning.communication import CommunicationPlan, communication_optimal
from isac_mission.planning.feasibility import MovingTargets, SlotConstraints, operating_area
from isac_mission.planning.margins import target_clearance_m
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.pcrb import Objective, PlanningObjective, SensingParams, SumObjective
from isac_mission.types import FloatArray, IntArray, SlotPlan, SolveReport

if TYPE_CHECKING:
    from isac_mission.planning.kit import SolverKit


@renamed_fields(
    prev_xy="prev_xy_m",
    prev_eta="prev_bandwidth_share",
    prev_assoc="prev_bs_of_uav",
    prev_velocity="prev_velocity_mps",
    keep_out_xy="keep_out_xy_m",
)
@dataclass(frozen=True)
class SlotInput:
    """What the planner knows at the start of slot n (positions in the scenario's planar frame).

    prev_xy_m [M, 2]: where the UAVs are (q_{n-1}), m; prev_bandwidth_share [M]: last slot's
    shares; prev_bs_of_uav [M] or None: last slot's BS per UAV; targets: the targets the plan is
    for (tracking/beliefs.py), at least one: the objective is the sum of their weighted
    tr(PCRB), the exact check keeps 14j from each along the legs, and the first, `lead`, is the
    one the convex subproblem's 14j rows, the fallback's evasion and the horizon's NLP follow
    (docs/model.md, "Planning for several targets"); prev_velocity_mps [M, 2] or None: the vehicles'
    velocities now (used when planner.accel_limit_mps2 or planner.vehicle_model is set);
    keep_out_xy_m [L, 2] or None: points every planned UAV keeps D_s from (vehicles outside this
    plan, other tracks; the kit must be built with n_keep_out = L); prev_plan: last slot's plan
    (the horizon's warm start), None at the first slot.

    The names before units were added (prev_xy, prev_eta, prev_assoc, prev_velocity,
    keep_out_xy) are accepted as keywords and readable as attributes, with a DeprecationWarning;
    they go in the next release.
    """

    prev_xy_m: FloatArray
    prev_bandwidth_share: FloatArray
    prev_bs_of_uav: IntArray | None
    targets: tuple[TargetBelief, ...]
    prev_velocity_mps: FloatArray | None = None
    keep_out_xy_m: FloatArray | None = None
    prev_plan: SlotPlan | None = None

    def __post_init__(self) -> None:
        if not self.targets:
            raise ValueError("a slot input needs at least one target belief")

    @property
    def lead(self) -> TargetBelief:
        """The target the solvers' 14j rows follow: the first of `targets`."""
        return self.targets[0]


@dataclass(frozen=True)
class SlotProblem:
    """One slot's problem, shared by every method.

    inp: the slot's input; scenario; bs_of_uav [M]: the association (P1-F.1, or last slot's with
    planner.association = "keep"); ballistic_xy_m [M, 2] or None: where the vehicles coast to
    (inside the 14h disk and the operating area) when a dynamics limit is set; constraints: the
    exact 14a-14j set with the slot's clearance; max_step_m: V_max dt, or 0 for a method that does
    not move the UAVs; communication: the communication-optimal plan at that step;
    objective: tr(PCRB) at the predicted state (measurement_only for the CRB-criterion), the
    weighted sum over the input's targets when it has several (`targets_objective`);
    started_s: the perf_counter time planning began (for SolveReport.solve_s).
    """

    inp: SlotInput
    scenario: Scenario
    bs_of_uav: IntArray
    ballistic_xy_m: FloatArray | None
    constraints: SlotConstraints
    max_step_m: float
    communication: CommunicationPlan
    objective: Objective
    started_s: float = field(default_factory=time.perf_counter)

    def elapsed_s(self) -> float:
        """Wall time since planning of this slot began, s."""
        return time.perf_counter() - self.started_s

    def plan(self, xy: FloatArray, eta: FloatArray, report: SolveReport) -> SlotPlan:
        """The SlotPlan of waypoints xy [M, 2] and shares eta [M], its bound by the full
        objective (prior included, also for the CRB-criterion)."""
        return SlotPlan(
            uav_xy_m=xy,
            bs_of_uav=self.bs_of_uav,
            bandwidth_share=eta,
            pcrb_trace=self.objective.with_prior().value(xy, eta),
            report=report,
        )

    def link_infeasible_reason(self) -> str | None:
        """Why no plan can meet 14a (the communication-optimal worst rate below R_th), or None."""
        s = self.scenario
        comm = self.communication
        if comm.worst_rate_bps >= s.r_th:
            return None
        return (
            f"infeasible: communication-optimal worst rate R_c* = {comm.worst_rate_bps / 1e6:.3f} "
            f"Mbit/s < R_th = {s.r_th / 1e6:.3f} Mbit/s"
        )


def slot_association(inp: SlotInput, kit: SolverKit) -> IntArray:
    """The slot's UAV-BS association [M]: P1-F.1 with rounding from q_n-1, or last slot's with
    planner.association "keep" (docs/model.md)."""
    s = kit.scenario
    if s.planner.association == "keep" and inp.prev_bs_of_uav is not None:
        return inp.prev_bs_of_uav
    return associate(
        inp.prev_xy_m, s.bs_xy, capacity=s.n_a, dH=s.dH, rho0=s.rho0, B=s.B, lp=kit.association
    )


def build_slot_problem(
    inp: SlotInput, kit: SolverKit, *, moves: bool = True, measurement_only: bool = False
) -> SlotProblem:
    """The slot's problem for a method that moves the UAVs (moves) or keeps them where they are,
    with the objective tr((J_pred + J_M)^-1), or tr(J_M^-1) with measurement_only."""
    started_s = time.perf_counter()
    s = kit.scenario
    cfg = s.planner
    n_keep_out = 0 if inp.keep_out_xy_m is None else len(inp.keep_out_xy_m)
    if n_keep_out != kit.n_keep_out:
        raise ValueError(f"{n_keep_out} keep-out points, but the kit is built for {kit.n_keep_out}")
    assoc = slot_association(inp, kit)
    serving = s.bs_xy[assoc]
    ballistic = None
    reach_m = VehicleModel.of(s).reach_radius_m if cfg.vehicle_model else np.inf
    if not cfg.vehicle_model and cfg.accel_limit_mps2 is not None:
        reach_m = cfg.accel_limit_mps2 * s.dt**2 / 4
    if np.isfinite(reach_m) and inp.prev_velocity_mps is not None:
        # Where the vehicles coast to, pulled inside the 14h disk: a vehicle a little faster than
        # the planner's V_max has to slow down anyway.
        coast = inp.prev_velocity_mps * s.dt
        norm = np.linalg.norm(coast, axis=1, keepdims=True)
        coast = coast * np.minimum(1.0, s.v_max * s.dt * (1 - 1e-9) / np.maximum(norm, 1e-12))
        # ... and inside the operating area: a vehicle heading out at the edge must stop too.
        ballistic = np.clip(inp.prev_xy_m + coast, *operating_area(s))
    x_pred = inp.lead.state_pred
    cons = SlotConstraints(
        inp.prev_xy_m,
        serving,
        s.bs_xy,
        x_pred[:2],
        s,
        ballistic_xy=ballistic,
        accel_radius_m=reach_m if ballistic is not None else np.inf,
        keep_out_xy=inp.keep_out_xy_m if n_keep_out else None,
        target_clearance_m=slot_clearance_m(inp, s),
        target_velocity_mps=x_pred[2:4],
        start_velocity_mps=inp.prev_velocity_mps,
        target_motion=inp.lead.motion,
        other_targets=moving_targets(inp.targets[1:], s),
    )
    step = s.v_max * s.dt if moves else 0.0
    comm = communication_optimal(
        inp.prev_xy_m, serving, max_step_m=step, dH=s.dH, rho0=s.rho0, B=s.B
    )
    objective = targets_objective(inp.targets, kit.sensing, measurement_only=measurement_only)
    return SlotProblem(
        inp=inp,
        scenario=s,
        bs_of_uav=assoc,
        ballistic_xy_m=ballistic,
        constraints=cons,
        max_step_m=step,
        communication=comm,
        objective=objective,
        started_s=started_s,
    )


def targets_objective(
    targets: tuple[TargetBelief, ...], sensing: SensingParams, *, measurement_only: bool = False
) -> Objective:
    """What every method plans and the fallback policy judges a plan by: tr(PCRB) of the one
    target, or the sum over the targets of weight tr(PCRB) (measurement_only: tr(J_M^-1), the
    CRB-criterion's), each at its predicted state."""
    parts = tuple(
        PlanningObjective(b.prior_information, b.state_pred, sensing, measurement_only)
        for b in targets
    )
    weights = tuple(b.weight for b in targets)
    if len(parts) == 1 and weights[0] == 1.0:
        return parts[0]
    return SumObjective(parts, weights)


def with_end_velocity(plan: SlotPlan, inp: SlotInput, s: Scenario) -> SlotPlan:
    """The plan with, under planner.vehicle_model, the mean-velocity leg's end velocity
    (q_n - q_{n-1}) / dt as uav_velocity_mps [M, 2] when the method gave none (docs/model.md,
    "Vehicle model")."""
    if not s.planner.vehicle_model or plan.uav_velocity_mps is not None:
        return plan
    end_v = VehicleModel.of(s).end_velocity(inp.prev_xy_m, plan.uav_xy_m)
    return dataclasses.replace(plan, uav_velocity_mps=end_v)


def slot_clearance_m(inp: SlotInput, s: Scenario) -> float:
    """The slot's 14j clearance from the lead target (`belief_clearance_m`)."""
    return belief_clearance_m(inp.lead, s)


def belief_clearance_m(belief: TargetBelief, s: Scenario) -> float:
    """The 14j clearance (planning/margins.py) from a target, for its predicted covariance
    (prior_information^-1 when its belief has none)."""
    cov = belief.cov_pred
    if cov is None and s.planner.safety_margin != "none":
        cov = belief.covariance()
    return target_clearance_m(s, cov)


def moving_targets(beliefs: tuple[TargetBelief, ...], s: Scenario) -> MovingTargets | None:
    """The targets `beliefs` as the exact check's moving targets (each its predicted state,
    clearance and motion model), None for none."""
    if not beliefs:
        return None
    return MovingTargets(
        np.array([b.state_pred for b in beliefs], dtype=float),
        np.array([belief_clearance_m(b, s) for b in beliefs]),
        tuple(b.motion for b in beliefs),
    )


def warm_up_input(kit: SolverKit) -> SlotInput:
    """A slot input at the scenario's start (keep-out points far outside the area: present for
    the solvers' shapes, never binding), for planning once before the first real slot."""
    s = kit.scenario
    return SlotInput(
        prev_xy_m=s.uav_start_xy,
        prev_bandwidth_share=np.full(s.M, 1.0 / s.M),
        prev_bs_of_uav=None,
        targets=(TargetBelief(s.x0, np.asarray(np.linalg.inv(s.P0), dtype=float), s.motion),),
        keep_out_xy_m=np.full((kit.n_keep_out, 2), -1e6) if kit.n_keep_out else None,
    )


class PlansOnceToWarmUp:
    """A planner whose `prepare` plans one slot from `warm_up_input`: every problem it uses is
    then built and solved once, so the first real slot does not pay for compilation."""

    def plan(self, inp: SlotInput, kit: SolverKit) -> SlotPlan:
        raise NotImplementedError

    def prepare(self, kit: SolverKit) -> None:
        self.plan(warm_up_input(kit), kit)
