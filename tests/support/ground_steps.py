"""The ground loop's mission state driven slot by slot without a bus (tests only): plan and
commit a slot as the loop does, and a processed slot as the trace of tracks records it."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from isac_mission.planning.slot import Method
from isac_mission.planning.tracks import TracksPlan
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.ground.mission import ArrivedReport, ArrivedTruth, MissionState
from isac_mission.service.ground.tracefile import track_set_slot
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, Gaussian, SlotPlan


def plan_slot_of(
    mission: MissionState,
    uav_xy: FloatArray,
    uav_v: FloatArray | None = None,
    excluded: tuple[int, ...] = (),
    method: Method | None = None,
    commit: bool = True,
) -> tuple[int, SlotPlan]:
    """(planned_for, plan) of the next slot from uav_xy [M, 2] (m) and uav_v [M, 2] (m/s),
    without the `excluded` vehicles, committed unless `commit` is False."""
    job = mission.next_job(uav_xy, uav_v, excluded)
    if method is not None:
        job = replace(job, method=method)
    planned = job.run_tracks()
    if commit:
        mission.commit(job, planned)
    return planned.planned_for, planned.plan


def commit_plan(
    mission: MissionState,
    planned_for: int,
    plan: SlotPlan,
    uav_xy: FloatArray,
    uav_v: FloatArray | None = None,
) -> None:
    """Commit a plan made elsewhere (an earlier run's) for the next slot, planned from uav_xy
    [M, 2] (m) with velocities uav_v [M, 2] (m/s)."""
    mission.commit(mission.next_job(uav_xy, uav_v), TracksPlan(planned_for, None, plan))


def processed(
    mission: MissionState,
    n: int,
    msgs: Mapping[int, ArrivedReport],
    truth: ArrivedTruth | None,
    fallback_xy: FloatArray,
) -> TracksSlot:
    """Slot n processed, as the trace of tracks records it."""
    return track_set_slot(mission.process(n, msgs, truth, fallback_xy))


def predictions_of(targets: tuple[TargetBelief, ...]) -> tuple[TrackPrediction, ...]:
    """Confirmed tracks 1, 2, ... predicted as `targets` (a belief without a predicted
    covariance: the inverse of its prior information)."""
    return tuple(
        TrackPrediction(
            i,
            True,
            Gaussian(
                b.state_pred,
                np.linalg.inv(b.prior_information) if b.cov_pred is None else b.cov_pred,
            ),
            b.prior_information,
        )
        for i, b in enumerate(targets, start=1)
    )
