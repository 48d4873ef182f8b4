"""The ground loop's state, without I/O: belief, bound, and the plan for the next slot.

Slot convention (as sim/world.py and wire/codec.py): plan n carries the waypoints flown during
(n-1, n] and the shares used for slot n's detections; after the detections of slot n are folded in,
the ground plans slot n+1. `MissionState` runs the slot recursion of `tracking/cycle.py`, as
`experiment/closed_loop.py` does offline, split at the points where the live service waits for the
network: `next_job` predicts (the plan is made on the planner's thread), `process` updates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.planning.fleet import KitCache, PlanningJob, active_part
from isac_mission.planning.slot import Method, SolverKit
from isac_mission.records import SlotRecord
from isac_mission.tracking.cycle import CycleModel, SlotPrediction, TrackState, predict, update
from isac_mission.tracking.pcrb import Bound
from isac_mission.types import (
    Detections,
    FloatArray,
    Gaussian,
    IntArray,
    SlotPlan,
    SolveReport,
)


def job_prediction(job: PlanningJob) -> SlotPrediction:
    """The slot prediction a planning job was made from: its one target's belief."""
    (target,) = job.targets
    assert target.cov_pred is not None
    return SlotPrediction(Gaussian(target.state_pred, target.cov_pred), target.prior_information)


@dataclass(frozen=True)
class PendingSlot:
    """What was decided for slot n before its measurements: prediction and plan."""

    slot: int
    predicted: SlotPrediction
    plan: SlotPlan
    start_xy: FloatArray | None = None
    """[M, 2] m: where the planner planned from (None: no plan of this loop)."""
    start_velocity: FloatArray | None = None
    """[M, 2] m/s: the velocities it was given (None: none)."""
    planned_around: tuple[int, ...] = ()
    """The vehicles the plan left out (PlanningJob.excluded)."""

    @property
    def prediction(self) -> Gaussian:
        """The EKF prediction of the slot."""
        return self.predicted.prediction


LEG_CHAIN_WITHIN_M = 3.0
"""A vehicle within this distance of last plan's waypoint is following its plan (m)."""


def leg_start_state(
    measured_xy: FloatArray,
    measured_v: FloatArray,
    last: SlotPlan,
    followed: Sequence[int],
    boundary_xy: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Where the next leg of each vehicle starts: [M, 2] positions (m) and velocities (m/s).

    The bridge flies each smooth leg from the previous leg's goal and end velocity, the plan's
    own end state (service/bridge/setpoints.py), not from where the vehicle is: a vehicle
    trails its setpoint by its tracking error (about 1-2 m on the receding horizon's
    accelerating legs). Planning from the measured position then capped the next waypoint at
    V_max dt from a point behind the leg's real start, and the vehicles lost that much every
    slot (live `horizon` flew 6 % shorter steps than its offline twin, whose vehicles are where
    it planned them; docs/performance.md, "Live against offline"). So the vehicles in
    `followed` that were within LEG_CHAIN_WITHIN_M of `last`'s waypoint at the slot boundary
    (boundary_xy [M, 2], the slot's detection positions, where finite; else measured_xy: a
    telemetry sample taken after the boundary is ahead of it by the time since) start from its
    waypoint and end velocity; the others (off their plan, or `last` has no end velocity or
    came too late to be flown) from their measured state."""
    xy, v = np.array(measured_xy, dtype=float), np.array(measured_v, dtype=float)
    end_v = last.uav_velocity_mps
    if end_v is None or last.report.fallback == "late" or not followed:
        return xy, v
    where = xy if boundary_xy is None else np.where(np.isfinite(boundary_xy), boundary_xy, xy)
    idx = np.asarray(followed, dtype=np.int64)
    near = np.linalg.norm(where[idx] - last.uav_xy_m[idx], axis=1) <= LEG_CHAIN_WITHIN_M
    chained = idx[near]
    xy[chained] = last.uav_xy_m[chained]
    v[chained] = np.asarray(end_v)[chained]
    return xy, v


class MissionState:
    """Belief and bound after the last processed slot, and the pending plan of the next one."""

    def __init__(self, s: Scenario, kit: SolverKit, method: Method, initial: Gaussian) -> None:
        self.scenario = s
        self.kit = kit
        self.method: Method = method
        self.model = CycleModel.from_scenario(s)
        self.belief = initial
        self.bound = Bound.from_covariance(initial.P.copy())
        self.slot = 0
        self.eta: FloatArray = np.full(s.M, 1.0 / s.M)
        self.assoc: IntArray | None = None
        self.pending: PendingSlot | None = None
        self.kits = KitCache(kit, method)
        self.last_plan: tuple[int, tuple[int, ...], SlotPlan] | None = None
        """(slot, active vehicles, plan) of the last committed plan: the next job's prev_plan
        when the next slot follows it with the same active vehicles."""

    @classmethod
    def resumed(cls, s: Scenario, kit: SolverKit, method: Method, last: SlotRecord) -> MissionState:
        """Continue after a trace's last complete slot (its P, J, estimate, shares, association)."""
        state = cls(s, kit, method, Gaussian(np.asarray(last.target_est), np.asarray(last.P)))
        state.bound = Bound.from_information(np.asarray(last.J))
        state.slot = last.slot
        state.eta = np.asarray(last.bandwidth_share, dtype=float)
        state.assoc = np.asarray(last.assoc, dtype=np.int64)
        return state

    @property
    def done(self) -> bool:
        return self.slot >= self.scenario.N

    def next_job(
        self,
        uav_xy: FloatArray,
        uav_v: FloatArray | None = None,
        excluded: tuple[int, ...] = (),
        boundary_xy: FloatArray | None = None,
        operator_held: tuple[int, ...] = (),
    ) -> PlanningJob:
        """Predict slot n+1: the planning job from the UAVs' current positions uav_xy [M, 2]
        (and velocities uav_v [M, 2], for a dynamics-aware planner), planning without the
        `excluded` vehicles (planning/fleet.py; `operator_held`: those an operator took out).
        Nothing changes until `commit`. A vehicle that
        follows last slot's plan starts from that plan's end state (`leg_start_state`; where
        the vehicles were at the slot boundary: boundary_xy [M, 2], NaN = unknown). The
        job carries the planner's prev_plan: last slot's plan when the active vehicles are the
        same (over them only), else None."""
        predicted = predict(self.model, TrackState(self.belief, self.bound))
        excluded = tuple(sorted(excluded))
        active = tuple(m for m in range(self.scenario.M) if m not in excluded)
        xy = np.asarray(uav_xy, dtype=float)
        v = None if uav_v is None else np.asarray(uav_v, dtype=float)
        prev_plan = None
        if self.last_plan is not None:
            slot, last_active, plan = self.last_plan
            if slot == self.slot and last_active == active:
                prev_plan = active_part(plan, active)
            if slot == self.slot and v is not None:
                followed = [m for m in active if m in last_active]
                xy, v = leg_start_state(xy, v, plan, followed, boundary_xy)
        return PlanningJob(
            slot=self.slot + 1,
            method=self.method,
            kits=self.kits,
            uav_xy=xy,
            uav_v=v,
            prev_eta=self.eta,
            prev_assoc=self.assoc,
            targets=(predicted.belief(self.model.motion),),
            excluded=excluded,
            prev_plan=prev_plan,
            operator_held=tuple(sorted(operator_held)),
        )

    def commit(self, job: PlanningJob, plan: SlotPlan) -> PendingSlot:
        """Adopt `plan` (from job.run(), or a fallback) as the plan of slot n+1."""
        if job.slot != self.slot + 1:
            raise ValueError(f"job for slot {job.slot}, but the next slot is {self.slot + 1}")
        predicted = job_prediction(job)
        self.pending = PendingSlot(job.slot, predicted, plan, job.uav_xy, job.uav_v, job.excluded)
        self.last_plan = (job.slot, job.active, plan)
        return self.pending

    def plan_next(
        self, uav_xy: FloatArray, uav_v: FloatArray | None = None, excluded: tuple[int, ...] = ()
    ) -> PendingSlot:
        """next_job, run and commit in one call."""
        job = self.next_job(uav_xy, uav_v, excluded)
        return self.commit(job, job.run())

    def renew_kits(self) -> None:
        """Plan on fresh solver kits, for the current scenario, from now on (a timed-out
        planner thread keeps the old); the IPOPT problems are kept (SolverKit.renewed)."""
        self.kit = self.kit.renewed(self.scenario)
        self.kits = KitCache(self.kit, self.method)

    def set_scenario(self, s: Scenario) -> None:
        """Plan from now on with `s` (e.g. an operator's new R_th); same M and geometry."""
        if s.M != self.scenario.M:
            raise ValueError(f"the new scenario has M = {s.M}, the mission {self.scenario.M}")
        self.scenario = s
        self.model = CycleModel.from_scenario(s)
        self.renew_kits()

    def skip(
        self,
        det: Detections,
        eta_used: FloatArray,
        compute_xy: FloatArray,
        status: str,
        reason: str,
    ) -> SlotRecord:
        """Slot n = slot + 1 ran without a plan of this loop (startup.py): drop the pending plan,
        predict, fold in what arrived (det, NaN = missing) as `process` does, and record status
        and reason. A UAV without a detection gets a null position in the record: compute_xy
        [M, 2] (finite) is used for the computation only, where it contributes nothing."""
        n = self.slot + 1
        if det.slot != n:
            raise ValueError(f"slot {det.slot} is not the next slot {n}")
        predicted = predict(self.model, TrackState(self.belief, self.bound))
        self.last_plan = None  # this slot had no plan of ours: the next one starts afresh
        known = np.isfinite(det.uav_xy_m)
        xy = np.where(known, det.uav_xy_m, np.nan)
        assoc = self.assoc if self.assoc is not None else np.full(self.scenario.M, -1)
        plan = SlotPlan(
            xy, assoc, eta_used, float("nan"), SolveReport(status, reason, fallback=status)
        )
        self.pending = PendingSlot(n, predicted, plan)
        record = self.process(det, eta_used, np.asarray(compute_xy, dtype=float))
        return SlotRecord.from_dict(record.to_dict() | {"uav_xy": xy.tolist(), "plan_xy": None})

    def process(self, det: Detections, eta_used: FloatArray, fallback_xy: FloatArray) -> SlotRecord:
        """Fold in slot n's detections (NaN = missing: a partial update) and advance the bound.

        eta_used [M]: the shares the measurements were taken with; fallback_xy [M, 2]: where a UAV
        was when its detection (which carries the position) did not arrive.
        """
        pending = self.pending
        if pending is None or det.slot != pending.slot:
            raise ValueError(f"slot {det.slot} is not the planned slot {self.slot + 1}")
        uav_xy = np.where(np.isfinite(det.uav_xy_m), det.uav_xy_m, fallback_xy)
        pred = pending.prediction
        z = np.concatenate([det.range_m, det.radial_velocity_mps])
        updated = update(
            self.model,
            TrackState(self.belief, self.bound),
            pending.predicted,
            self.kit.sensing,
            z,
            uav_xy,
            eta_used,
        )
        self.belief, self.bound = updated.state.belief, updated.state.bound
        r_used = updated.r_used
        self.slot = det.slot
        plan = pending.plan
        # A UAV measured with a share although this plan had it out (BS -1): the world was still
        # on an earlier plan (this one came late), whose association goes with those shares.
        assoc = plan.bs_of_uav
        if self.assoc is not None:
            assoc = np.where((assoc < 0) & (np.asarray(eta_used) > 0), self.assoc, assoc)
        self.eta, self.assoc = plan.bandwidth_share, plan.bs_of_uav
        self.pending = None
        rep = plan.report
        return SlotRecord(
            slot=det.slot,
            method=self.method,
            status=rep.status,
            uav_xy_m=uav_xy,
            bandwidth_share=np.asarray(eta_used, dtype=float),
            assoc=assoc,
            target_true=None,
            target_est=self.belief.x,
            target_pred=pred.x,
            r_diag=r_used,
            pcrb_trace=self.bound.trace,
            solve_ms=rep.solve_s * 1e3,
            P=self.belief.P,
            J=self.bound.J,
            plan_xy=plan.uav_xy_m,
            plan_pcrb_trace=plan.pcrb_trace,
            plan_velocity=plan.uav_velocity_mps,
            reason=rep.reason or None,
            fallback=rep.fallback or None,
            plan_start_xy=pending.start_xy,
            plan_start_velocity=pending.start_velocity,
            extra={
                "pcrb_pos": self.bound.position_trace,
                "pcrb_vel": self.bound.velocity_trace,
                "received": int(np.count_nonzero(det.received)),
            }
            | ({"planned_around": list(pending.planned_around)} if pending.planned_around else {}),
        )
