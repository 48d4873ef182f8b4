"""The one tracker interface: predict the targets for the next slot, update them with the slot's
reports, and each track's bound.

A slot of any tracker: `predict` advances every track one slot and returns what the planner
needs of each (`TrackPrediction`: its prediction and the bound's prior information); the plan is
flown; `update` folds in the slot's reports, one per UAV (measurements [k_m, 2] of range m and
radial velocity m/s), steps each track's bound and returns the tracks after it (`SlotTracking`).

Two implementations, picked from the scenario by `tracking/factory.py`:
- `LabelledTracker` (here): the paper's one target whose every detection is known to be its own
  (at most one measurement per UAV): the EKF and the PCRB of `tracking/cycle.py`, one track with
  ID 1, confirmed from the start;
- `MultiTargetTracker` (tracking/multi_target.py): unlabelled reports with misses and clutter,
  JPDA or GNN, initiation, confirmation and deletion, the bound with origin uncertainty.

Pure: numpy only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from isac_mission.model.motion import MotionModel
from isac_mission.model.radar import SensingParams
from isac_mission.tracking.beliefs import PathOffsets, TargetBelief
from isac_mission.tracking.cycle import CycleModel, SlotPrediction, TrackState, predict, update
from isac_mission.tracking.pcrb import Bound
from isac_mission.types import FloatArray, Gaussian

LABELLED_TRACK_ID = 1
"""The ID of the labelled tracker's one track."""


@dataclass(frozen=True)
class TrackPrediction:
    """One track before a slot's reports: track_id, confirmed, prediction (x [4], P [4, 4]),
    prior_information J_pred [4, 4] = (F C F^T + W)^-1 of its bound (what planning sees), and
    existence in (0, 1]: how far the track is on its way to confirmation (a confirmed track 1; a
    tentative one its hits over the hits that confirm it); manoeuvre: an IMM track's predicted
    curve (`TargetBelief.manoeuvre`), None otherwise."""

    track_id: int
    confirmed: bool
    prediction: Gaussian
    prior_information: FloatArray
    existence: float = 1.0
    manoeuvre: PathOffsets | None = None

    def belief(self, motion: MotionModel) -> TargetBelief:
        """The track as the planner takes it (tracking/beliefs.py), predicted by `motion` (and
        its manoeuvre, an IMM track's curve)."""
        return TargetBelief(
            self.prediction.x,
            self.prior_information,
            motion,
            self.prediction.P,
            track_id=self.track_id,
            manoeuvre=self.manoeuvre,
        )


@dataclass(frozen=True)
class TrackEstimate:
    """One track after a slot: track_id (stable, never reused), confirmed, belief (x [4] in m
    and m/s, P [4, 4]), bound: its PCRB (with origin uncertainty for unlabelled reports,
    tracking/origin_uncertainty.py), weight: its association weight this slot (sum over UAVs of
    1 - beta_0; a labelled track: the UAVs whose report held a measurement); variances [2M] or
    None: the measurement variances its update used (m^2 then m^2/s^2, NaN where none; the
    labelled tracker's)."""

    track_id: int
    confirmed: bool
    belief: Gaussian
    bound: Bound
    weight: float
    variances: FloatArray | None = None


@dataclass(frozen=True)
class SlotTracking:
    """What one slot's update did: tracks [T] after it (confirmed and tentative), started and
    deleted: the IDs started and deleted this slot."""

    tracks: tuple[TrackEstimate, ...]
    started: tuple[int, ...]
    deleted: tuple[int, ...]

    @property
    def confirmed(self) -> tuple[TrackEstimate, ...]:
        return tuple(t for t in self.tracks if t.confirmed)


class Tracker(Protocol):
    """A tracker of any number of targets: `add_confirmed` for a target whose prior is known,
    then `predict` and `update` each slot."""

    @property
    def labels_reports(self) -> bool:
        """True when every UAV's report is of the one target, labelled (the paper's detection
        model): the tracker holds one track, and its slot carries the labelled target's fields
        (docs/trace.md) and goes out as a `track` (docs/bus.md)."""
        ...

    def add_confirmed(self, belief: Gaussian) -> int:
        """Start a confirmed track from a known prior (x [4], P [4, 4]; its bound from the same
        covariance); returns its ID."""
        ...

    def predict(self) -> tuple[TrackPrediction, ...]:
        """Advance every track and its bound one slot; the tracks' predictions (tentative and
        confirmed)."""
        ...

    def saved(self) -> object:
        """What the tracker carries to the next slot (after `update`), for a restart to
        continue from (`tracking/factory.restored_tracker`)."""
        ...

    def update(
        self,
        reports: Sequence[FloatArray],
        uav_xy_m: FloatArray,
        eta: FloatArray,
        sensing: SensingParams,
    ) -> SlotTracking:
        """Fold in one slot's reports [M] (arrays [k_m, 2] of range m and radial velocity m/s)
        taken at uav_xy_m [M, 2] with shares eta [M]; step each track's bound. Call after
        `predict`."""
        ...


def labelled_measurements(reports: Sequence[FloatArray]) -> FloatArray:
    """z [2M] (ranges then radial velocities, NaN = missing) from labelled reports [M], each
    [k_m, 2] with k_m <= 1."""
    M = len(reports)
    z = np.full(2 * M, np.nan)
    for m, report in enumerate(reports):
        rows = np.asarray(report, dtype=float).reshape(-1, 2)
        if len(rows) > 1:
            raise ValueError(f"UAV {m}: {len(rows)} measurements of the one labelled target")
        if len(rows):
            z[m], z[M + m] = rows[0]
    return z


def labelled_reports(z: FloatArray) -> tuple[FloatArray, ...]:
    """The labelled reports [M] ([1, 2] each; [0, 2] where both range and velocity are
    missing) of z [2M] (ranges then radial velocities, NaN = missing)."""
    M = len(z) // 2
    out = []
    for m in range(M):
        row = np.array([[z[m], z[M + m]]], dtype=float)
        out.append(row if np.isfinite(row).any() else np.zeros((0, 2)))
    return tuple(out)


class LabelledTracker:
    """The paper's tracker of one target whose detections are labelled (tracking/cycle.py: the
    EKF and the PCRB, the same numbers): one track, ID 1, confirmed from its prior."""

    labels_reports = True

    def __init__(self, model: CycleModel, state: TrackState | None = None) -> None:
        self.model = model
        self.state = state
        self.prediction: SlotPrediction | None = None

    @classmethod
    def from_prior(cls, model: CycleModel, prior: Gaussian) -> LabelledTracker:
        """A tracker started from the target's prior (the bound from the same covariance)."""
        tracker = cls(model)
        tracker.add_confirmed(prior)
        return tracker

    def add_confirmed(self, belief: Gaussian) -> int:
        if self.state is not None:
            raise ValueError("the labelled tracker follows one target: it has one already")
        self.state = TrackState(belief, Bound.from_covariance(belief.P.copy()))
        return LABELLED_TRACK_ID

    def saved(self) -> TrackState | None:
        """The one track's belief and bound (None: no track yet)."""
        return self.state

    def predict(self) -> tuple[TrackPrediction, ...]:
        if self.state is None:
            return ()
        self.prediction = predict(self.model, self.state)
        pred = self.prediction
        return (TrackPrediction(LABELLED_TRACK_ID, True, pred.prediction, pred.prior),)

    def update(
        self,
        reports: Sequence[FloatArray],
        uav_xy_m: FloatArray,
        eta: FloatArray,
        sensing: SensingParams,
    ) -> SlotTracking:
        if self.state is None or self.prediction is None:
            raise ValueError("update before predict")
        z = labelled_measurements(reports)
        step = update(self.model, self.state, self.prediction, sensing, z, uav_xy_m, eta)
        self.state = step.state
        measured = float(np.sum(np.isfinite(step.r_used[: len(reports)])))
        estimate = TrackEstimate(
            LABELLED_TRACK_ID, True, step.state.belief, step.state.bound, measured, step.r_used
        )
        return SlotTracking((estimate,), (), ())
