"""How a target is believed to move: the one interface every predictor of the target takes.

A motion model gives, for a step of dt_s seconds, the transition F [4, 4] and the process noise
W [4, 4] of the state x = [x_m, y_m, vx_mps, vy_mps], and the predicted mean and covariance along
a path of times (the leg samples of a slot, the slots of a horizon). The trackers, the bound's
recursion, the planner's predicted target points and clearances, the offline truth and the
simulated world all take one; none of them writes a motion model's equations itself.

`ConstantVelocity` (eq. 3-4) is the one implementation. For a target that switches between modes
(the interacting multiple model, tracking/imm.py): the coordinated turn with the turn rate in the
state, x5 = [x, y, vx, vy, omega] (`ct_transition`, its Jacobian `ct_jacobian`), and the long-run
share of each mode (`stationary_probabilities`). Pure numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from isac_mission.model.kinematics import process_noise, transition_matrix
from isac_mission.types import FloatArray


@dataclass(frozen=True)
class PredictedPath:
    """The predicted target along times_s [T] (s after the belief's instant): means [T, 4]
    (m, m/s) and covariances [T, 4, 4]."""

    times_s: FloatArray
    means: FloatArray
    covariances: FloatArray


class MotionModel(Protocol):
    """A target's motion model: state [4] = (x_m, y_m, vx_mps, vy_mps)."""

    def transition(self, dt_s: float) -> FloatArray:
        """F [4, 4]: the mean's step over dt_s (s; negative steps back)."""
        ...

    def process_noise(self, dt_s: float) -> FloatArray:
        """W [4, 4]: the covariance the step of dt_s (s) adds."""
        ...

    def position_after(self, state: Any, t_s: float | FloatArray) -> Any:
        """The predicted position [2] t_s seconds after the instant of state [4] (negative:
        before it), for a numpy array or a symbolic vector (CasADi SX: the planner's NLPs build
        on it); t_s [S, 1] of numpy times gives the positions [S, 2]."""
        ...

    def predicted_path(
        self, mean: FloatArray, covariance: FloatArray | None, times_s: FloatArray
    ) -> PredictedPath:
        """The prediction from (mean [4], covariance [4, 4]; None: zeros) at each of times_s
        [T] (s after their instant, non-negative)."""
        ...


@dataclass(frozen=True)
class ConstantVelocity:
    """Constant velocity with white-acceleration noise of intensity kappa_m2ps3 (eq. 3-4)."""

    kappa_m2ps3: float

    def transition(self, dt_s: float) -> FloatArray:
        return transition_matrix(dt_s)

    def process_noise(self, dt_s: float) -> FloatArray:
        return process_noise(dt_s, self.kappa_m2ps3)

    def position_after(self, state: Any, t_s: float | FloatArray) -> Any:
        return state[:2] + t_s * state[2:]

    def predicted_path(
        self, mean: FloatArray, covariance: FloatArray | None, times_s: FloatArray
    ) -> PredictedPath:
        # F(t) P F(t)^T + W(t) block by block (pp, pv, vv: position, cross, velocity), in closed
        # form so that each time costs a few vector operations.
        t = np.asarray(times_s, dtype=float).reshape(-1)
        x = np.asarray(mean, dtype=float)
        P = np.zeros((4, 4)) if covariance is None else np.asarray(covariance, dtype=float)
        means = np.empty((len(t), 4))
        means[:, :2] = x[None, :2] + t[:, None] * x[None, 2:]
        means[:, 2:] = x[None, 2:]
        pp, pv, vv = P[:2, :2], P[:2, 2:], P[2:, 2:]
        eye = np.eye(2)[None]
        kappa = self.kappa_m2ps3
        tt = t[:, None, None]
        covariances = np.empty((len(t), 4, 4))
        covariances[:, :2, :2] = (
            pp[None]
            + tt * (pv + pv.T)[None]
            + (t**2)[:, None, None] * vv[None]
            + (kappa * t**3 / 3)[:, None, None] * eye
        )
        cross = pv[None] + tt * vv[None] + (kappa * t**2 / 2)[:, None, None] * eye
        covariances[:, :2, 2:] = cross
        covariances[:, 2:, :2] = np.transpose(cross, (0, 2, 1))
        covariances[:, 2:, 2:] = vv[None] + (kappa * t)[:, None, None] * eye
        return PredictedPath(t, means, covariances)


def stationary_probabilities(switching: FloatArray) -> FloatArray:
    """pi [r]: the stationary distribution of a mode-switching Markov chain, switching [r, r]
    (row i: the probabilities of each mode after mode i); the left eigenvector of eigenvalue 1,
    normalised to sum 1."""
    P = np.asarray(switching, dtype=float)
    r = P.shape[0]
    # pi (P - I) = 0 with sum(pi) = 1, solved in the least-squares sense (exact for an ergodic
    # chain; a reducible one gets the minimum-norm solution).
    A = np.vstack([(P - np.eye(r)).T, np.ones((1, r))])
    b = np.concatenate([np.zeros(r), [1.0]])
    pi = np.linalg.lstsq(A, b, rcond=None)[0]
    pi = np.clip(pi, 0.0, None)
    return np.asarray(pi / pi.sum(), dtype=float)


_SERIES_BELOW = 0.1
"""|omega dt| below which the turn's coefficients use their Taylor series (error < 1e-17)."""


def _turn_coefficients(u: float) -> tuple[float, float, float, float]:
    """(sin u / u, (1 - cos u) / u and their derivatives in u) at u = omega dt; Taylor series
    for |u| < _SERIES_BELOW, so that omega -> 0 is smooth and exact to float precision."""
    if abs(u) < _SERIES_BELOW:
        u2 = u * u
        a = 1 - u2 / 6 * (1 - u2 / 20 * (1 - u2 / 42 * (1 - u2 / 72)))
        b = u / 2 * (1 - u2 / 12 * (1 - u2 / 30 * (1 - u2 / 56 * (1 - u2 / 90))))
        da = -u / 3 * (1 - u2 / 10 * (1 - u2 / 28 * (1 - u2 / 54)))
        db = 0.5 * (1 - u2 / 4 * (1 - u2 / 18 * (1 - u2 / 40 * (1 - u2 / 70))))
        return a, b, da, db
    s, c = math.sin(u), math.cos(u)
    return s / u, (1 - c) / u, (u * c - s) / u**2, (u * s - (1 - c)) / u**2


def ct_transition(x: FloatArray, dt_s: float) -> FloatArray:
    """f(x) [5]: the coordinated turn of x [5] over dt_s (s) at its own omega; omega constant.
    Equals model/targets.coordinated_turn_matrix on [x, y, vx, vy], and CV at omega = 0."""
    w = float(x[4])
    a, b, _, _ = _turn_coefficients(w * dt_s)
    s, c = math.sin(w * dt_s), math.cos(w * dt_s)
    vx, vy = float(x[2]), float(x[3])
    return np.array(
        [
            x[0] + dt_s * (a * vx - b * vy),
            x[1] + dt_s * (b * vx + a * vy),
            c * vx - s * vy,
            s * vx + c * vy,
            w,
        ]
    )


def ct_jacobian(x: FloatArray, dt_s: float) -> FloatArray:
    """F [5, 5] = d ct_transition / dx at x [5] (analytic; smooth through omega = 0)."""
    w, vx, vy, T = float(x[4]), float(x[2]), float(x[3]), dt_s
    a, b, da, db = _turn_coefficients(w * T)
    s, c = math.sin(w * T), math.cos(w * T)
    return np.array(
        [
            [1.0, 0.0, T * a, -T * b, T * T * (da * vx - db * vy)],
            [0.0, 1.0, T * b, T * a, T * T * (db * vx + da * vy)],
            [0.0, 0.0, c, -s, -T * (s * vx + c * vy)],
            [0.0, 0.0, s, c, T * (c * vx - s * vy)],
            [0.0, 0.0, 0.0, 0.0, 1.0],
        ]
    )
