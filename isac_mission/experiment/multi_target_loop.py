"""The offline closed loop of the multi-target path (docs/model.md, "Several targets"): predict
every track, plan, fly, take each UAV's unlabelled report, update the tracks, for N slots.

The planner is the same `plan_slot` as the single-target loop's, given the confirmed tracks:
the objective is the sum of their tr(PCRB) (`SlotInput.other_targets`); the confirmed track
nearest to the fleet is the target the plan's safety rule follows along each leg, and every
other track, confirmed or tentative, is a keep-out point at its predicted position that every UAV
keeps D_s from (the nearest `KEEP_OUT_CAPACITY`). With no confirmed track the fleet holds where it
is. The truth, the detections and their random numbers are model/targets.py's,
model/detections.py's and `draw_multi_target_noise`'s, common to every method of a run.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.model.detections import UavReport, unlabelled_detections
from isac_mission.model.run_noise import MultiTargetNoise
from isac_mission.model.targets import TargetPaths, target_paths
from isac_mission.planning.association import association_costs, optimal_assignment
from isac_mission.planning.slot import Method, SlotInput, SolverKit, plan_slot
from isac_mission.tracking.multi_target import (
    MultiTargetTracker,
    TrackerSettings,
    TrackEstimate,
    TrackPrediction,
)
from isac_mission.types import FloatArray, Gaussian, IntArray, SlotPlan, SolveReport

KEEP_OUT_CAPACITY = 8
"""How many tracks besides the planned-around one every UAV keeps D_s from (the nearest to the
fleet); the kit's problems are built for this many keep-out points."""

FAR_AWAY_M = -1e6
"""Where the unused keep-out points are (no UAV comes near)."""

SINGLE_TARGET_METHODS = ("horizon",)
"""Methods that plan for one target only (their NLPs are one target's): refused on this path."""


@dataclass(frozen=True)
class MultiTargetSlot:
    """One slot: plan (flown); uav_xy_m [M, 2] and bandwidth_share [M] where the reports were
    taken; truth [T, 4] every target's true state (NaN rows: not in the scene); reports [M]
    (with their true origins, for metrics); tracks: the tentative and confirmed tracks after the
    update; planned_for: the ID of the track the safety rule followed (0: none, the fleet held)."""

    slot: int
    method: str
    plan: SlotPlan
    uav_xy_m: FloatArray
    bandwidth_share: FloatArray
    truth: FloatArray
    reports: tuple[UavReport, ...]
    tracks: tuple[TrackEstimate, ...]
    planned_for: int


@dataclass(frozen=True)
class MultiTargetRun:
    """One run of one method: its slots 1..N and the targets' paths (states [N + 1, T, 4])."""

    method: str
    seed: int
    paths: TargetPaths
    slots: tuple[MultiTargetSlot, ...]


def multi_target_kit(s: Scenario) -> SolverKit:
    """A SolverKit for the multi-target loop (KEEP_OUT_CAPACITY keep-out points)."""
    return SolverKit(s, n_keep_out=KEEP_OUT_CAPACITY)


def target_radar_gains(s: Scenario) -> FloatArray:
    """[T] each target's SNR^s d^4 (m^4) from its RCS."""
    return np.array([s.with_changes(rcs_m2=t.rcs_m2).radar_gain for t in s.targets])


def check_multi_target_method(method: str) -> None:
    """Raise ConfigError for a method that cannot plan for several targets."""
    if method in SINGLE_TARGET_METHODS:
        raise ConfigError(
            f"method {method!r} plans for one target (its NLP is one target's bound); on the "
            "multi-target path plan with proposed, proposed-sca, sd, aba, crb or comm"
        )


def run_multi_target(
    s: Scenario,
    method: Method,
    noise: MultiTargetNoise,
    kit: SolverKit,
    on_slot: Callable[[MultiTargetSlot], None] | None = None,
) -> MultiTargetRun:
    """Fly one mission of N slots of a multi-target scenario with the given method; `kit` from
    `multi_target_kit`."""
    check_multi_target_method(method)
    if kit.n_keep_out != KEEP_OUT_CAPACITY:
        raise ValueError(f"the kit must be built with n_keep_out={KEEP_OUT_CAPACITY}")
    if s.detection is None:
        raise ConfigError(f"{s.mission_id}: the multi-target loop needs a detection model")
    paths = target_paths(s.targets, s.dt, s.kappa, s.N, noise.target_normals)
    gains = target_radar_gains(s)
    tracker = MultiTargetTracker(TrackerSettings.from_scenario(s))
    uav_xy, eta = s.uav_start_xy.copy(), np.full(s.M, 1.0 / s.M)
    assoc: IntArray | None = None
    velocity = np.zeros((s.M, 2))
    plan: SlotPlan | None = None
    slots = []
    for n in range(1, s.N + 1):
        for t, spec in enumerate(s.targets):
            if spec.prior_known and spec.first_slot == n - 1:
                x = paths.states[n - 1, t] + noise.initial_errors[t]
                tracker.add_confirmed(Gaussian(x=x, P=s.P0.copy()))
        predictions = tracker.predict()
        planned_for, plan = _plan(s, method, kit, predictions, uav_xy, eta, assoc, velocity, plan)
        if plan.uav_velocity_mps is not None:
            velocity = plan.uav_velocity_mps
        else:
            velocity = (plan.uav_xy_m - uav_xy) / s.dt
        uav_xy, eta, assoc = plan.uav_xy_m, plan.bandwidth_share, plan.bs_of_uav
        reports = unlabelled_detections(
            paths.states[n], gains, uav_xy, eta, kit.sensing, s.detection, noise.slots[n - 1]
        )
        update = tracker.update([r.measurements for r in reports], uav_xy, eta, kit.sensing)
        slot = MultiTargetSlot(
            n,
            method,
            plan,
            uav_xy,
            eta,
            paths.states[n],
            tuple(reports),
            update.tracks,
            planned_for,
        )
        slots.append(slot)
        if on_slot is not None:
            on_slot(slot)
    return MultiTargetRun(method, noise.seed, paths, tuple(slots))


def _plan(
    s: Scenario,
    method: Method,
    kit: SolverKit,
    predictions: tuple[TrackPrediction, ...],
    uav_xy: FloatArray,
    eta: FloatArray,
    assoc: IntArray | None,
    velocity: FloatArray,
    prev_plan: SlotPlan | None,
) -> tuple[int, SlotPlan]:
    """(the ID of the track planned around, the slot's plan) for the tracks' predictions."""
    confirmed = [p for p in predictions if p.confirmed]
    if not confirmed:
        return 0, _hold(s, uav_xy, eta, assoc)

    def fleet_distance(p: TrackPrediction) -> float:
        return float(np.min(np.linalg.norm(uav_xy - p.prediction.x[:2], axis=1)))

    primary = min(confirmed, key=fleet_distance)
    others = sorted((p for p in predictions if p is not primary), key=fleet_distance)
    keep_out = np.full((KEEP_OUT_CAPACITY, 2), FAR_AWAY_M)
    for i, p in enumerate(others[:KEEP_OUT_CAPACITY]):
        keep_out[i] = p.prediction.x[:2]
    inp = SlotInput(
        prev_xy_m=uav_xy,
        prev_bandwidth_share=eta,
        prev_bs_of_uav=assoc,
        target_state_pred=primary.prediction.x,
        prior_information=primary.prior_information,
        prev_velocity_mps=velocity,
        keep_out_xy_m=keep_out,
        target_cov_pred=primary.prediction.P,
        prev_plan=prev_plan,
        other_targets=tuple(
            (p.prediction.x, p.prior_information) for p in confirmed if p is not primary
        ),
    )
    return primary.track_id, plan_slot(inp, kit, method)


def _hold(s: Scenario, uav_xy: FloatArray, eta: FloatArray, assoc: IntArray | None) -> SlotPlan:
    """Every UAV holds where it is with last slot's shares and BSs (the communication-optimal
    BSs at the first slot): no confirmed track to plan for."""
    if assoc is None:
        costs = association_costs(uav_xy, s.bs_xy, dH=s.dH, rho0=s.rho0, B=s.B)
        assoc = optimal_assignment(costs, s.n_a)
    report = SolveReport("ok", "no confirmed track: the fleet holds", fallback="no track")
    return SlotPlan(uav_xy.copy(), assoc, eta.copy(), float("nan"), report)
