"""The offline closed loop of the multi-target path (docs/model.md, "Several targets"): predict
every track, plan, fly, take each UAV's unlabelled report, update the tracks, for N slots.

The planner is `planning.multi_target.plan_for_tracks` (the single-target methods given the
confirmed tracks, as the live ground loop plans). The truth, the detections and their random numbers are model/targets.py's,
model/detections.py's and `draw_multi_target_noise`'s, common to every method of a run.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.model.detections import unlabelled_detections
from isac_mission.model.run_noise import MultiTargetNoise
from isac_mission.model.targets import TargetPaths, target_paths, target_radar_gains
from isac_mission.planning.multi_target import check_multi_target_method, plan_for_tracks
from isac_mission.planning.slot import Method, SolverKit
from isac_mission.records.multi_target import MultiTargetSlot
from isac_mission.tracking.multi_target import MultiTargetTracker, TrackerSettings
from isac_mission.types import Gaussian, IntArray, SlotPlan

__all__ = ["MultiTargetRun", "MultiTargetSlot", "run_multi_target"]


@dataclass(frozen=True)
class MultiTargetRun:
    """One run of one method: its slots 1..N and the targets' paths (states [N + 1, T, 4])."""

    method: str
    seed: int
    paths: TargetPaths
    slots: tuple[MultiTargetSlot, ...]


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
        planned_for, plan = plan_for_tracks(
            s, method, kit, predictions, uav_xy, eta, assoc, velocity, plan
        )
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
