"""The slot recursion, written once: predict -> plan -> update -> bound (Section II-C).

Slot n starts from the belief (EKF posterior) and the bound (PCRB information J) after slot n-1:

1. `predict`: the EKF prediction of slot n and the planner's prior information
   (J_pred of the PCRB recursion, or the inverse of the EKF's predicted covariance when the
   scenario's `bound_prior` is "ekf");
2. the planner turns that prediction into the slot's plan (`plan_slot`, or the live service's
   planning job on its own thread);
3. `update`: slot n's measurements z [2M] (ranges then radial velocities, NaN = missing) taken
   at uav_xy [M, 2] with shares eta [M] are folded into the belief, and the bound takes the same
   step with the same variances (NaN where a measurement did not arrive or has no variance).

The offline loop (`experiment/closed_loop.py`) runs the three back to back; the live ground loop
(`service/ground/mission.py`) calls `predict` and `update` on either side of its network waits
(the plan is made on the planner's thread in between). Pure: numpy only, no clock, no RNG.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from isac_mission.model.motion import MotionModel
from isac_mission.tracking.beliefs import TargetBelief
from isac_mission.tracking.ekf import ekf_predict, ekf_update
from isac_mission.tracking.pcrb import (
    Bound,
    SensingParams,
    bound_step,
    predict_information,
    scaled_inverse,
)
from isac_mission.types import FloatArray, Gaussian

if TYPE_CHECKING:
    from isac_mission.config import Scenario


@dataclass(frozen=True)
class CycleModel:
    """The recursion's constants: F, W [4, 4] of the target's motion model over one slot, the
    planner's prior ("pcrb" or "ekf"), the iterated EKF's number of iterations and the motion
    model itself (what the planner predicts the target with between slot instants)."""

    F: FloatArray
    W: FloatArray
    bound_prior: str
    ekf_iterations: int
    motion: MotionModel

    @classmethod
    def from_scenario(cls, s: Scenario) -> CycleModel:
        """The constants a scenario resolves to."""
        return cls(
            F=s.motion.transition(s.dt),
            W=s.motion.process_noise(s.dt),
            bound_prior=s.bound_prior,
            ekf_iterations=s.ekf_iterations,
            motion=s.motion,
        )


@dataclass(frozen=True)
class TrackState:
    """The belief (EKF posterior, x [4] in m and m/s, P [4, 4]) and the bound after a slot."""

    belief: Gaussian
    bound: Bound


@dataclass(frozen=True)
class SlotPrediction:
    """What slot n knows before its measurements: the EKF prediction and the planner's prior
    information prior [4, 4] (J_pred, or the scaled inverse of the predicted covariance)."""

    prediction: Gaussian
    prior: FloatArray

    def belief(self, motion: MotionModel) -> TargetBelief:
        """The prediction as the planner takes it (tracking/beliefs.py), predicted by `motion`."""
        return TargetBelief(self.prediction.x, self.prior, motion, self.prediction.P)


@dataclass(frozen=True)
class SlotUpdate:
    """After slot n's measurements: the new state and the variances used, r_used [2M]
    (m^2 then m^2/s^2; NaN = no measurement)."""

    state: TrackState
    r_used: FloatArray


def predict(model: CycleModel, state: TrackState) -> SlotPrediction:
    """Step 1: the EKF prediction of the next slot and the planner's prior."""
    prediction = ekf_predict(state.belief, model.F, model.W)
    J_pred = predict_information(state.bound, model.F, model.W)
    prior = J_pred if model.bound_prior == "pcrb" else scaled_inverse(prediction.P)
    return SlotPrediction(prediction, prior)


def update(
    model: CycleModel,
    state: TrackState,
    pred: SlotPrediction,
    sensing: SensingParams,
    z: FloatArray,
    uav_xy: FloatArray,
    eta: FloatArray,
) -> SlotUpdate:
    """Step 3: fold in z [2M] measured at uav_xy [M, 2] with shares eta [M], and step the bound.

    The variances come from the predicted target (the truth is not the filter's): r_diag [2M]
    at the predicted ranges, NaN where z is missing or the variance is not finite (eta = 0).
    """
    x_pred = pred.prediction.x
    with np.errstate(divide="ignore"):  # eta = 0: a vehicle outside the plan senses nothing
        r_diag = sensing.variances(np.linalg.norm(x_pred[None, :2] - uav_xy, axis=1), eta)
    r_used = np.where(np.isfinite(z) & np.isfinite(r_diag), r_diag, np.nan)
    belief = ekf_update(pred.prediction, z, uav_xy, r_used, model.ekf_iterations)
    bound = bound_step(state.bound, model.F, model.W, x_pred, uav_xy, r_used)
    return SlotUpdate(TrackState(belief, bound), r_used)
