"""The offline closed loop of Section II-C, for any number of targets: predict, plan, fly,
measure, update, for N slots.

Every method of one Monte Carlo run flies the same scene (`model/scene.py`: the targets' truth
and the run's random numbers: the initial estimate errors, the process noise and the
measurement draws, scaled by each method's own noise standard deviations). The tracker and the
scene come from `tracking/factory.py`: the paper's labelled target (the EKF and PCRB of
`tracking/cycle.py`) or several targets' unlabelled reports (`tracking/multi_target.py`). The
planner is the one the live service calls (`planning/tracks.plan_tracks` over
`plan_slot`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from isac_mission.config import Scenario, single_target_problem
from isac_mission.errors import ConfigError
from isac_mission.model.detections import UavReport
from isac_mission.model.run_noise import RunNoise
from isac_mission.model.run_noise import draw_run_noise as draw_run_noise
from isac_mission.model.scene import Scene
from isac_mission.model.scene import true_trajectory as true_trajectory
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method, SlotInput
from isac_mission.planning.tracks import plan_tracks
from isac_mission.tracking.factory import keep_out_tracks, scene_for, tracker_for
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.priorities import scripted_priorities
from isac_mission.tracking.tracker import SlotTracking, Tracker, TrackEstimate, TrackPrediction
from isac_mission.types import FloatArray, IntArray, SlotPlan


@dataclass(frozen=True)
class SlotOutcome:
    """Everything one slot produced.

    slot_input: what the planner was given (None: the fleet held, no confirmed track); plan: the
    plan flown; uav_xy [M, 2], eta [M]: where and with which shares the reports were taken;
    truth [T, 4]: every target's true state (NaN rows: not in the scene); reports [M]: each
    UAV's report (with its true origins, for metrics); predictions: the tracks' predictions the
    plan was made from; tracking: the tracks after the update; planned_for: the ID of the track
    the plan's safety rule followed (0: none).

    The labelled target's trace fields (docs/trace.md) read its one track: target_true,
    target_pred, target_est [4]; r_diag [2M] (the variances used, NaN = missing); P [4, 4];
    bound.
    """

    slot: int
    method: str
    slot_input: SlotInput | None
    plan: SlotPlan
    uav_xy: FloatArray
    eta: FloatArray
    truth: FloatArray
    reports: tuple[UavReport, ...]
    predictions: tuple[TrackPrediction, ...]
    tracking: SlotTracking
    planned_for: int

    @property
    def _track(self) -> TrackEstimate:
        (track,) = self.tracking.tracks
        return track

    @property
    def target_true(self) -> FloatArray:
        return np.asarray(self.truth[0])

    @property
    def target_pred(self) -> FloatArray:
        (prediction,) = self.predictions
        return prediction.prediction.x

    @property
    def target_est(self) -> FloatArray:
        return self._track.belief.x

    @property
    def r_diag(self) -> FloatArray:
        variances = self._track.variances
        assert variances is not None  # the labelled tracker's
        return variances

    @property
    def P(self) -> FloatArray:  # noqa: N802 (the trace's name)
        return self._track.belief.P

    @property
    def bound(self) -> Bound:
        return self._track.bound


@dataclass(frozen=True)
class RunResult:
    """Per-slot arrays of one run of one method (slots 1..N).

    est, true [N, 4]; pcrb [N, 4, 4] (C = J^-1); solve_s [N]; status [N]; uav_xy [N, M, 2];
    eta [N, M]; assoc [N, M]; fallback [N]: why the method's answer was not flown ("" = it was).
    """

    method: str
    seed: int
    est: FloatArray
    true: FloatArray
    pcrb: FloatArray
    solve_s: FloatArray
    status: list[str]
    uav_xy: FloatArray
    eta: FloatArray
    assoc: IntArray
    fallback: list[str] = field(default_factory=list)

    @classmethod
    def of_outcomes(cls, method: str, seed: int, slots: Sequence[SlotOutcome]) -> RunResult:
        """The per-slot arrays of a run's labelled track."""
        return cls(
            method=method,
            seed=seed,
            est=np.array([o.target_est for o in slots]),
            true=np.array([o.target_true for o in slots]),
            pcrb=np.array([o.bound.C for o in slots]),
            solve_s=np.array([o.plan.report.solve_s for o in slots], dtype=float),
            status=[o.plan.report.status for o in slots],
            fallback=[o.plan.report.fallback for o in slots],
            uav_xy=np.array([o.uav_xy for o in slots]),
            eta=np.array([o.eta for o in slots]),
            assoc=np.array([o.plan.bs_of_uav for o in slots], dtype=np.int64),
        )


def fly_offline(
    s: Scenario,
    method: Method,
    scene: Scene,
    tracker: Tracker,
    kit: SolverKit,
    on_slot: Callable[[SlotOutcome], None] | None = None,
) -> tuple[SlotOutcome, ...]:
    """Fly one mission of N slots of `scene` with the given planning method and tracker (both
    from `tracking/factory.py`); `kit` built with `keep_out_tracks(s)` keep-out points."""
    uav_xy, eta = s.uav_start_xy.copy(), np.full(s.M, 1.0 / s.M)
    assoc: IntArray | None = None
    velocity = np.zeros((s.M, 2))
    plan: SlotPlan | None = None
    out = []
    for n in range(1, s.N + 1):
        for prior in scene.priors(n - 1):
            tracker.add_confirmed(prior)
        predictions = tracker.predict()
        planned = plan_tracks(
            s,
            method,
            kit,
            predictions,
            uav_xy,
            eta,
            assoc,
            velocity,
            plan,
            keep_out_tracks=keep_out_tracks(s),
            priorities=scripted_priorities(s.priority_changes, n),
        )
        plan = planned.plan
        if plan.uav_velocity_mps is not None:
            velocity = plan.uav_velocity_mps  # the vehicle model's planned end velocity
        else:
            velocity = (plan.uav_xy_m - uav_xy) / s.dt  # each leg flown at constant velocity
        uav_xy, eta, assoc = plan.uav_xy_m, plan.bandwidth_share, plan.bs_of_uav
        reports = scene.reports(n, uav_xy, eta, kit.sensing)
        tracking = tracker.update([r.measurements for r in reports], uav_xy, eta, kit.sensing)
        outcome = SlotOutcome(
            slot=n,
            method=method,
            slot_input=planned.slot_input,
            plan=plan,
            uav_xy=uav_xy,
            eta=eta,
            truth=scene.truth(n),
            reports=reports,
            predictions=predictions,
            tracking=tracking,
            planned_for=planned.planned_for,
        )
        out.append(outcome)
        if on_slot is not None:
            on_slot(outcome)
    return tuple(out)


def run_closed_loop(
    s: Scenario,
    method: Method,
    noise: RunNoise,
    kit: SolverKit,
    on_slot: Callable[[SlotOutcome], None] | None = None,
    truth: FloatArray | None = None,
) -> RunResult:
    """Fly one mission of N slots of the scenario's labelled target with the given planning
    method (`fly_offline`); returns per-slot results. truth [N + 1, 4]: the target's true states
    x_0..x_N (a scripted target); None: the motion model driven by the run's process noise
    (`true_trajectory`). A scenario of several targets raises ConfigError
    (config.single_target_problem)."""
    problem = single_target_problem(s)
    if problem is not None:
        raise ConfigError(f"{s.mission_id}: {problem}")
    scene = scene_for(s, noise, truth)
    slots = fly_offline(s, method, scene, tracker_for(s), kit, on_slot)
    return RunResult.of_outcomes(method, noise.seed, slots)


def record_slot_inputs(
    s: Scenario, method: Method, noise: RunNoise, kit: SolverKit
) -> tuple[RunResult, list[SlotInput]]:
    """One run, and the planner's input of every slot (to replay or time the planner alone)."""
    inputs: list[SlotInput] = []

    def keep(o: SlotOutcome) -> None:
        assert o.slot_input is not None  # the labelled target is always planned for
        inputs.append(o.slot_input)

    result = run_closed_loop(s, method, noise, kit, keep)
    return result, inputs
