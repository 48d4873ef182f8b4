"""The ground loop's state, without I/O: the tracks, and the plan for the next slot.

Slot convention (as sim/world.py and wire/codec.py): plan n carries the waypoints flown during
(n-1, n] and the shares used for slot n's reports; after the reports of slot n are folded in,
the ground plans slot n+1. `MissionState` runs the slot recursion of the offline loop
(`experiment/closed_loop.fly_offline`) on the scenario's tracker (`tracking/factory.py`: the
paper's labelled EKF and PCRB, or the tracker of several targets), split at the points where the
live service waits for the network: `next_job` predicts (the plan is made on the planner's
thread), `commit` adopts the plan, `process` updates, `skip` traces a slot the world ran without
a plan of this loop. The operator's priority of each track (tracking/priorities.py) weighs it in
the plans: the scenario's script (`priorities:`) and `set_priority` change it from the next
planned slot on.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.detections import UavReport
from isac_mission.planning.fleet import KitCache, PlanningJob, active_part
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method
from isac_mission.planning.tracks import TracksPlan, check_method
from isac_mission.timebase import SlotTimeline
from isac_mission.tracking.factory import keep_out_tracks, tracker_for
from isac_mission.tracking.multi_target import TrackerState
from isac_mission.tracking.priorities import Priorities, apply_changes
from isac_mission.tracking.tracker import (
    LABELLED_TRACK_ID,
    SlotTracking,
    Tracker,
    TrackPrediction,
)
from isac_mission.types import FloatArray, Gaussian, IntArray, SlotPlan, SolveReport

NO_ORIGIN = -2
"""A measurement's origin when the world's truth did not say (no truth for the slot)."""

HELD = "held"
"""Status of a slot the world ran without a plan of this loop, with reports."""
UNOBSERVED = "unobserved"
"""Status of such a slot with no report: positions unknown (null), prediction only."""


class ArrivedReport(Protocol):
    """One UAV's report of a slot as it arrived (a `detection` or a `detection_set`)."""

    @property
    def uav_xy_m(self) -> FloatArray:
        """[2] where the UAV measured (m)."""
        ...

    @property
    def bandwidth_share(self) -> float:
        """The share eta it measured with."""
        ...

    @property
    def report(self) -> FloatArray:
        """[k, 2] its measurements (range m, radial velocity m/s)."""
        ...


class ArrivedTruth(Protocol):
    """The world's truth of a slot (a `truth` or a `truth_set`): evaluation only."""

    @property
    def target_states(self) -> FloatArray:
        """[T, 4] every target's state (m, m/s); NaN rows: not in the scene."""
        ...

    @property
    def measurement_origins(self) -> tuple[tuple[int, ...], ...]:
        """Per UAV, the target of each measurement (-1: a false alarm); () when not given."""
        ...


@dataclass(frozen=True)
class PendingSlot:
    """What was decided for slot n before its reports: the tracks' predictions and the plan."""

    slot: int
    predictions: tuple[TrackPrediction, ...]
    plan: SlotPlan
    planned_for: int = 0
    """The ID of the track the plan's safety rule followed (0: none, the fleet held)."""
    start_xy: FloatArray | None = None
    """[M, 2] m: where the planner planned from (None: no plan of this loop)."""
    start_velocity: FloatArray | None = None
    """[M, 2] m/s: the velocities it was given (None: none)."""
    planned_around: tuple[int, ...] = ()
    """The vehicles the plan left out (PlanningJob.excluded)."""
    skipped: bool = False
    """The world ran the slot without a plan of this loop (`MissionState.skip`)."""
    priorities: Priorities = field(default_factory=Priorities)
    """The operator's priorities the plan was made with (those in force for a skipped slot)."""


@dataclass(frozen=True)
class GroundSlot:
    """One slot as the ground loop processed it.

    plan: the plan flown (a skipped slot's: its status and the shares); uav_xy [M, 2]: where the
    reports were taken (a UAV without a report: where it was last seen; `known_xy` has NaN
    there); eta [M]: the shares they were taken with (a UAV without a report: its plan's);
    assoc [M]: the BS of each UAV while measuring; truth [T, 4] (NaN: not known); reports [M]
    (with the world's origins, NO_ORIGIN where not known); predictions: the tracks' predictions
    the plan was made from; tracking: the tracks after the update; received: the reports that
    arrived; saved: the tracker's state after the update (`Tracker.saved`: what a resume
    continues from); priorities: the operator's priorities the mission goes on with after the
    slot (what a resume continues with; the plan's are `pending.priorities`).
    """

    slot: int
    method: str
    pending: PendingSlot
    uav_xy: FloatArray
    known_xy: FloatArray
    eta: FloatArray
    assoc: IntArray
    truth: FloatArray
    truth_known: bool
    reports: tuple[UavReport, ...]
    tracking: SlotTracking
    received: int
    saved: object
    priorities: Priorities = field(default_factory=Priorities)

    @property
    def plan(self) -> SlotPlan:
        return self.pending.plan

    @property
    def predictions(self) -> tuple[TrackPrediction, ...]:
        return self.pending.predictions

    @property
    def planned_for(self) -> int:
        return self.pending.planned_for


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
    """The tracks after the last processed slot, and the pending plan of the next one.

    tracker: the scenario's (`tracker_for`) with no track yet; the known targets' tracks are
    started as the offline loop starts them (`start_known_tracks`). initial_errors [T, 4]: added
    to each known target's configured state to start its track (the offline twin's x_hat - x;
    None: start at the configured state, the cue)."""

    def __init__(
        self,
        s: Scenario,
        kit: SolverKit,
        method: Method,
        initial_errors: FloatArray | None = None,
        tracker: Tracker | None = None,
    ) -> None:
        check_method(s, method)
        self.scenario = s
        self.kit = kit
        self.method: Method = method
        self.tracker: Tracker = tracker_for(s) if tracker is None else tracker
        self.initial_errors = initial_errors
        self.slot = 0
        self.eta: FloatArray = np.full(s.M, 1.0 / s.M)
        self.assoc: IntArray | None = None
        self.pending: PendingSlot | None = None
        self.kits = KitCache(kit, method, keep_out_tracks(s))
        """Kits for the fleet without the excluded vehicles (their positions keep-out points
        beside the other tracks')."""
        self.last_plan: tuple[int, tuple[int, ...], SlotPlan] | None = None
        """(slot, active vehicles, plan) of the last committed plan: the next job's prev_plan
        when the next slot follows it with the same active vehicles."""
        self._predicted: tuple[TrackPrediction, ...] | None = None
        """The tracks predicted to slot + 1 (None: not yet): a plan dropped after a stall is
        made again from the same prediction."""
        self._started_at: int | None = None
        """The slot after which the known targets' tracks were last started."""
        self.priorities = Priorities()
        """The operator's priority of each track (tracking/priorities.py), as the next plan
        takes it."""
        self._script_through = 0
        """The last slot whose scripted priority changes (the scenario's) are applied."""
        self._seen_ids: set[int] = set()
        """Every track ID the tracker has given out that this state has seen."""
        self._last_job_slot = 0
        """The slot of the last planning job made (`next_job`)."""

    @classmethod
    def from_prior(
        cls, s: Scenario, kit: SolverKit, method: Method, prior: Gaussian
    ) -> MissionState:
        """A mission whose one known target's track starts from `prior` (x [4], P [4, 4])."""
        state = cls(s, kit, method)
        state.tracker.add_confirmed(prior)
        state._started_at = 0
        return state

    @classmethod
    def resumed(
        cls,
        s: Scenario,
        kit: SolverKit,
        method: Method,
        tracker: Tracker,
        slot: int,
        eta: FloatArray,
        assoc: IntArray,
        initial_errors: FloatArray | None = None,
        priorities: Priorities | None = None,
    ) -> MissionState:
        """Continue after a trace's slot line: the tracker as it was after `slot`'s update, the
        shares eta [M] and BSs assoc [M] of that slot's plan, the operator's priorities the
        mission went on with (None: every track 1; the scenario's scripted changes of later slots
        still to come); no last plan (the vehicles were not flying this loop's plan). ValueError
        when the line does not fit `s`."""
        if slot >= s.N:
            raise ValueError(f"slot {slot} is the mission's last ({s.N}): nothing to resume")
        eta, assoc = np.array(eta, dtype=float), np.array(assoc, dtype=np.int64)
        if eta.shape != (s.M,) or assoc.shape != (s.M,):
            raise ValueError(f"slot {slot}'s line is not for {s.M} UAVs")
        state = cls(s, kit, method, initial_errors, tracker)
        state.slot, state.eta, state.assoc = slot, eta, assoc
        state.priorities = Priorities() if priorities is None else priorities
        state._script_through = slot
        return state

    @property
    def done(self) -> bool:
        return self.slot >= self.scenario.N

    def slots_to_skip(self, t_s: float, t0_s: float) -> range:
        """The slots after the last processed one that the world has already run at t_s
        (mission start t0_s): they flew no plan of this loop."""
        world_slot = SlotTimeline(t0_s, self.scenario.dt).slot_of(t_s)
        return range(self.slot + 1, min(world_slot, self.scenario.N) + 1)

    def start_known_tracks(self) -> None:
        """Start a confirmed track for every known target that enters at the current slot
        (the offline loop's rule: before slot n + 1 is predicted, those of first slot n); once
        per slot (a plan dropped after a stall is made again)."""
        if self._started_at == self.slot:
            return
        self._started_at = self.slot
        s = self.scenario
        for t, spec in enumerate(s.targets):
            if spec.prior_known and spec.first_slot == self.slot:
                x = np.array(spec.x0, dtype=np.float64)
                if self.initial_errors is not None:
                    x = x + self.initial_errors[t]
                self.tracker.add_confirmed(Gaussian(x=x, P=s.P0.copy()))

    def predict(self) -> tuple[TrackPrediction, ...]:
        """Every track predicted to slot + 1 (the known targets' tracks started first); the
        tracker predicts once per slot, a second call returns the same predictions."""
        if self._predicted is None:
            self.start_known_tracks()
            self._predicted = self.tracker.predict()
            self._seen_ids.update(p.track_id for p in self._predicted)
        return self._predicted

    def set_priority(self, track_id: int, weight: float) -> None:
        """The operator's priority of track `track_id` from the next planned slot on: `weight`
        in [0, 10] (0: not planned for, still kept clear of; tracking/priorities.py).
        ValueError naming what is wrong: a weight out of [0, 10] or not a finite number, a track
        ID the tracker has never had ("no track 7")."""
        table = self.priorities.with_priority(track_id, weight)  # checks both values
        had = self.track_ids_had()
        if track_id not in had:
            so_far = ", ".join(map(str, sorted(had)[:20])) if had else "none yet"
            raise ValueError(
                f"no track {track_id}: the tracker has never had it (its tracks: {so_far})"
            )
        self.priorities = table

    @property
    def next_planned_slot(self) -> int:
        """The first slot whose plan a change made now (`set_priority`, `set_scenario`) goes
        into: the next slot, or the one after it when its planning job is already made."""
        return max(self.slot + 1, self._last_job_slot + 1)

    def track_ids_had(self) -> set[int]:
        """Every track ID the tracker has had so far (a tracker of several tracks gives them out
        in order, so those below its next ID; the labelled tracker's one, 1, once started)."""
        ids = set(self._seen_ids)
        saved = self.tracker.saved()
        if isinstance(saved, TrackerState):
            ids.update(range(1, saved.next_id))
        elif saved is not None and self.tracker.labels_reports:
            ids.add(LABELLED_TRACK_ID)
        return ids

    def _apply_script(self, slot: int) -> None:
        """Apply the scenario's scripted priority changes up to slot `slot` (once each)."""
        if slot > self._script_through:
            changes = self.scenario.priority_changes
            self.priorities = apply_changes(self.priorities, changes, self._script_through, slot)
            self._script_through = slot

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
        Nothing but the prediction changes until `commit`. A vehicle that follows last slot's
        plan starts from that plan's end state (`leg_start_state`; where the vehicles were at
        the slot boundary: boundary_xy [M, 2], NaN = unknown). The job carries the planner's
        prev_plan: last slot's plan when the active vehicles are the same (over them only),
        else None."""
        predictions = self.predict()
        self._apply_script(self.slot + 1)
        self._last_job_slot = self.slot + 1
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
            predictions=predictions,
            excluded=excluded,
            prev_plan=prev_plan,
            operator_held=tuple(sorted(operator_held)),
            priorities=self.priorities,
        )

    def commit(self, job: PlanningJob, planned: TracksPlan | SlotPlan) -> PendingSlot:
        """Adopt the plan (from job.run_tracks() or job.run(), or a fallback) as the plan of
        slot n+1."""
        if job.slot != self.slot + 1:
            raise ValueError(f"job for slot {job.slot}, but the next slot is {self.slot + 1}")
        if isinstance(planned, SlotPlan):
            planned = TracksPlan(_primary_id(job.predictions), None, planned)
        self.pending = PendingSlot(
            job.slot,
            job.predictions,
            planned.plan,
            planned.planned_for,
            job.uav_xy,
            job.uav_v,
            job.excluded,
            priorities=job.priorities,
        )
        self.last_plan = (job.slot, job.active, planned.plan)
        return self.pending

    def plan_next(
        self, uav_xy: FloatArray, uav_v: FloatArray | None = None, excluded: tuple[int, ...] = ()
    ) -> PendingSlot:
        """next_job, run and commit in one call."""
        job = self.next_job(uav_xy, uav_v, excluded)
        return self.commit(job, job.run_tracks())

    def renew_kits(self) -> None:
        """Plan on fresh solver kits, for the current scenario, from now on (a timed-out
        planner thread keeps the old); the IPOPT problems, the solve lock and the compiled
        cache are kept (SolverKit.renewed)."""
        self.kit = self.kit.renewed(self.scenario)
        self.kits = KitCache(self.kit, self.method, keep_out_tracks(self.scenario))

    def set_scenario(self, s: Scenario) -> None:
        """Plan from now on with `s` (e.g. an operator's new R_th); same M and geometry."""
        if s.M != self.scenario.M:
            raise ValueError(f"the new scenario has M = {s.M}, the mission {self.scenario.M}")
        self.scenario = s
        self.renew_kits()

    def skip(
        self,
        n: int,
        msgs: Mapping[int, ArrivedReport],
        truth: ArrivedTruth | None,
        compute_xy: FloatArray,
        why: str,
    ) -> GroundSlot:
        """Slot n = slot + 1 ran without a plan of this loop (after a resume or a stall:
        startup.py): its pending plan, if any, is dropped; the tracks are predicted (unless the
        pending plan's prediction already did) and take the reports that arrived, with the
        shares they were measured with. Status `held`, or `unobserved` when nothing arrived; a
        UAV without a report has a NaN `known_xy` (compute_xy [M, 2], finite, is used for the
        computation only, where it contributes nothing)."""
        s = self.scenario
        if n != self.slot + 1:
            raise ValueError(f"slot {n} is not the next slot {self.slot + 1}")
        predictions = self.predict()
        self._apply_script(n)
        known = np.full((s.M, 2), np.nan)
        eta = np.array(self.eta, dtype=float)
        for m, msg in msgs.items():
            known[m] = msg.uav_xy_m
            eta[m] = msg.bandwidth_share
        status = HELD if msgs else UNOBSERVED
        reason = (
            f"{status}: no plan of the ground loop for this slot ({why}); "
            f"{len(msgs)} of {s.M} reports"
        )
        assoc = self.assoc if self.assoc is not None else np.full(s.M, -1, dtype=np.int64)
        plan = SlotPlan(
            known, assoc, eta, float("nan"), SolveReport(status, reason, fallback=status)
        )
        self.pending = PendingSlot(n, predictions, plan, skipped=True, priorities=self.priorities)
        out = self.process(n, msgs, truth, np.asarray(compute_xy, dtype=float))
        self.last_plan = None  # this slot had no plan of ours: the next one starts afresh
        return out

    def process(
        self,
        n: int,
        msgs: Mapping[int, ArrivedReport],
        truth: ArrivedTruth | None,
        fallback_xy: FloatArray,
    ) -> GroundSlot:
        """Fold in slot n's reports (a UAV whose report did not arrive contributes nothing:
        share 0 for the tracker; fallback_xy [M, 2] is where it was) and advance to slot n."""
        pending = self.pending
        if pending is None or n != pending.slot:
            raise ValueError(f"slot {n} is not the planned slot {self.slot + 1}")
        s = self.scenario
        plan = pending.plan
        eta_used = np.array(plan.bandwidth_share, dtype=float)
        sensing_eta = np.zeros(s.M)
        uav_xy = np.array(fallback_xy, dtype=float)
        known = np.full((s.M, 2), np.nan)
        measurements: list[FloatArray] = []
        for m in range(s.M):
            msg = msgs.get(m)
            if msg is None:
                measurements.append(np.zeros((0, 2)))
                continue
            eta_used[m] = sensing_eta[m] = msg.bandwidth_share
            uav_xy[m] = known[m] = msg.uav_xy_m
            measurements.append(np.asarray(msg.report, dtype=float).reshape(-1, 2))
        tracking = self.tracker.update(measurements, uav_xy, sensing_eta, self.kit.sensing)
        self._seen_ids.update(t.track_id for t in tracking.tracks)
        self._seen_ids.update(tracking.started)
        origins = () if truth is None else truth.measurement_origins
        reports = tuple(
            UavReport(z, _origins(origins, m, len(z))) for m, z in enumerate(measurements)
        )
        T = len(s.targets)
        states = np.full((T, 4), np.nan) if truth is None else truth.target_states
        # A UAV measured with a share although this plan had it out (BS -1): the world was still
        # on an earlier plan (this one came late), whose association goes with those shares.
        assoc = plan.bs_of_uav
        if self.assoc is not None:
            assoc = np.where((assoc < 0) & (eta_used > 0), self.assoc, assoc)
        self.slot = n
        self.eta, self.assoc = plan.bandwidth_share, plan.bs_of_uav
        self.pending = None
        self._predicted = None
        return GroundSlot(
            slot=n,
            method=self.method,
            pending=pending,
            uav_xy=uav_xy,
            known_xy=known,
            eta=eta_used,
            assoc=np.asarray(assoc, dtype=np.int64),
            truth=np.asarray(states, dtype=float),
            truth_known=truth is not None,
            reports=reports,
            tracking=tracking,
            received=len(msgs),
            saved=self.tracker.saved(),
            priorities=self.priorities,
        )


def _primary_id(predictions: tuple[TrackPrediction, ...]) -> int:
    """The ID of the first confirmed track (0: none): the track a plan made outside
    `plan_tracks` (a hold) is recorded for."""
    return next((p.track_id for p in predictions if p.confirmed), 0)


def _origins(origins: tuple[tuple[int, ...], ...], m: int, k: int) -> IntArray:
    """[k] the origins of UAV m's k measurements, as the world's truth gave them."""
    if m < len(origins) and len(origins[m]) == k:
        return np.asarray(origins[m], dtype=np.int64)
    return np.full(k, NO_ORIGIN, dtype=np.int64)


__all__ = [
    "HELD",
    "UNOBSERVED",
    "GroundSlot",
    "MissionState",
    "PendingSlot",
    "leg_start_state",
]
