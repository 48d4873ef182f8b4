"""What the planner knows of one target at the start of a slot: the tracker's prediction of it.

Every tracker gives the planner a tuple of `TargetBelief`s (one for a single target), and the
planner reads the target only through them: the predicted state and covariance at the slot's
end, the bound's prior information there, the motion model that predicts the target at any other
instant (the leg samples, the horizon's slots), and the target's weight in the objective. Pure.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from isac_mission.model.motion import MotionModel, PredictedPath
from isac_mission.types import FloatArray


class PathOffsets(Protocol):
    """A manoeuvring belief's departure from the straight prediction of its motion model."""

    def offsets(self, n_slots: int) -> FloatArray:
        """[n_slots, 4] (m, m/s): the predicted state at the end of slot n + h minus F^h times
        the one at the end of slot n (h = 0..n_slots - 1; row 0 zeros)."""
        ...


@dataclass(frozen=True)
class TargetBelief:
    """One target predicted to the end of slot n (the instant its measurements are taken).

    state_pred [4]: (x_m, y_m, vx_mps, vy_mps); prior_information [4, 4]: the bound's prior
    information (J_pred, in the state's inverse squared units); motion: the motion model that
    predicted it; cov_pred [4, 4] or None: the tracker's predicted covariance (the safety rule;
    None: prior_information^-1); weight: the target's weight in the objective (the sum over
    targets of weight tr(PCRB)); track_id: the tracker's ID of it (0: the one labelled target);
    manoeuvre: a manoeuvring track's departure from motion's straight path over the next slots
    (the interacting multiple model's `ImmPath`: the receding horizon plans along it), None for
    a belief that the motion model predicts alone.
    """

    state_pred: FloatArray
    prior_information: FloatArray
    motion: MotionModel
    cov_pred: FloatArray | None = None
    weight: float = 1.0
    track_id: int = 0
    manoeuvre: PathOffsets | None = None

    def path_offsets(self, n_slots: int) -> FloatArray | None:
        """[n_slots, 4] (m, m/s): `PathOffsets.offsets` of the manoeuvre; None without one."""
        return None if self.manoeuvre is None else self.manoeuvre.offsets(n_slots)

    def position_at(self, t_s: float) -> Any:
        """The predicted position [2] t_s seconds after the prediction's instant (negative:
        before it)."""
        return self.motion.position_after(self.state_pred, t_s)

    def path(self, times_s: FloatArray) -> PredictedPath:
        """The prediction (means, covariances) at times_s [T] after the prediction's instant."""
        return self.motion.predicted_path(self.state_pred, self.cov_pred, times_s)

    def covariance(self) -> FloatArray:
        """The predicted covariance [4, 4]: cov_pred, or prior_information^-1 without one."""
        if self.cov_pred is not None:
            return self.cov_pred
        return np.asarray(np.linalg.inv(self.prior_information), dtype=float)
