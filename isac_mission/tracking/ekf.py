"""Extended Kalman filter for the constant-velocity target with range/Doppler measurements.

Built on filterpy's ExtendedKalmanFilter. The update linearises h once at the prediction (the
standard EKF) and processes the 2M independent scalar measurements one at a time against that
linearisation: algebraically the batch update for diagonal R, and numerically stable when R is tiny
(the literal eq. 8 model), where the batch innovation covariance is singular to working precision.
Missing measurements (NaN) are skipped: a partial update with what arrived.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from isac_mission.model.radar import measure, measurement_jacobian
from isac_mission.types import FloatArray, Gaussian


def _filter(belief: Gaussian, F: FloatArray, W: FloatArray) -> ExtendedKalmanFilter:
    kf = ExtendedKalmanFilter(dim_x=4, dim_z=1)
    kf.x = belief.x.astype(float).copy()
    kf.P = belief.P.astype(float).copy()
    kf.F = F
    kf.Q = W
    return kf


def _belief(kf: ExtendedKalmanFilter) -> Gaussian:
    P = np.asarray(kf.P, dtype=float)
    return Gaussian(x=np.asarray(kf.x, dtype=float).reshape(4).copy(), P=0.5 * (P + P.T))


def ekf_predict(belief: Gaussian, F: FloatArray, W: FloatArray) -> Gaussian:
    """x_{n|n-1} = F x, P_{n|n-1} = F P F^T + W (F, W [4, 4])."""
    kf = _filter(belief, F, W)
    kf.predict()
    return _belief(kf)


def ekf_update(
    prediction: Gaussian,
    z: FloatArray,
    uav_xy: FloatArray,
    r_diag: FloatArray,
    iterations: int = 1,
) -> Gaussian:
    """EKF update with measurements z [2M] (ranges then radial velocities; NaN = missing) taken
    from uav_xy [M, 2], with noise variances r_diag [2M] (non-finite = missing).

    iterations > 1 is the iterated EKF: the update is recomputed from the same prediction with h
    linearised at the previous iteration's estimate (Gauss-Newton on the MAP problem). It matters
    where the noise is far below the linearisation error (the literal eq. 8 model)."""
    post = _linearised_update(prediction, z, uav_xy, r_diag, prediction.x)
    for _ in range(iterations - 1):
        post = _linearised_update(prediction, z, uav_xy, r_diag, post.x)
    return post


def _linearised_update(
    prediction: Gaussian, z: FloatArray, uav_xy: FloatArray, r_diag: FloatArray, x_lin: FloatArray
) -> Gaussian:
    """The Kalman update of `prediction` with h linearised at x_lin [4]."""
    x0 = x_lin
    H_all = measurement_jacobian(x0, uav_xy)
    h_all = measure(x0, uav_xy)
    kf = _filter(prediction, np.eye(4), np.zeros((4, 4)))
    use = np.isfinite(z) & np.isfinite(r_diag)
    for i in np.flatnonzero(use):
        H_i = H_all[i : i + 1]
        h_i = h_all[i]

        def jac(_x: FloatArray, H_i: FloatArray = H_i) -> FloatArray:
            return H_i

        def hx(x: FloatArray, H_i: FloatArray = H_i, h_i: float = h_i) -> FloatArray:
            # h linearised at x_lin, so the sequence equals the batch (I)EKF update.
            return np.atleast_1d(h_i + H_i @ (np.asarray(x).reshape(4) - x0))

        kf.update(np.array([z[i]]), jac, hx, R=np.array([[r_diag[i]]]))
    return _belief(kf)


class TargetTracker:
    """Stateful EKF: predict() then update() each slot. F, W [4, 4]; the belief is a Gaussian."""

    def __init__(self, initial: Gaussian, F: FloatArray, W: FloatArray) -> None:
        self.belief = initial
        self.F = F
        self.W = W

    def predict(self) -> Gaussian:
        """Advance the belief one slot; returns and keeps the prediction."""
        self.belief = ekf_predict(self.belief, self.F, self.W)
        return self.belief

    def update(self, z: FloatArray, uav_xy: FloatArray, r_diag: FloatArray) -> Gaussian:
        """Fold in one slot's measurements (see ekf_update); returns and keeps the posterior."""
        self.belief = ekf_update(self.belief, z, uav_xy, r_diag)
        return self.belief
