"""Posterior Cramér-Rao bound (eq. 9-12) with the Tichavsky recursion, and its planning objective.

The bound's information J_n = (F J_{n-1}^-1 F^T + W)^-1 + H^T R^-1 H is kept on the full matrix
(eq. 11 as printed would forget past measurements: docs/model.md). H and R are evaluated at the
predicted state. The objective of (P1) is f(Q, eta) = tr(C) with C = J^-1 at that state; this module
gives f and its analytic gradients with respect to the UAV positions Q [M, 2] and shares eta [M].

The measurement information is a sum of rank-one terms J_M = sum_m a_m g_m g_m^T + b_m k_m k_m^T with
g_m = d(d_m)/dx, k_m = d(v_m)/dx, a_m = 1/sigma_d^2 and b_m = 1/sigma_v^2 (eq. 8).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.model.motion import MotionModel
from isac_mission.model.radar import SensingParams, measurement_directions
from isac_mission.types import FloatArray

__all__ = [
    "Bound",
    "PlanningObjective",
    "SensingParams",
    "measurement_directions",
    "scaled_inverse",
]


def scaled_inverse(A: FloatArray) -> FloatArray:
    """Inverse of a symmetric positive-definite matrix [n, n] via Jacobi (diagonal) scaling.

    Information matrices here mix entries of order 1e20 (literal eq. 8 ranges) with entries of
    order 1; scaling by the diagonal first keeps the inverse accurate to a few ulps.
    """
    s = 1.0 / np.sqrt(np.diag(A))
    scaled = A * s[:, None] * s[None, :]
    inv = np.linalg.inv(scaled) * s[:, None] * s[None, :]
    return np.asarray(0.5 * (inv + inv.T))


@dataclass(frozen=True)
class Bound:
    """The bound at one slot: information J [4, 4] and PCRB matrix C = J^-1 [4, 4]."""

    J: FloatArray
    C: FloatArray

    @classmethod
    def from_information(cls, J: FloatArray) -> Bound:
        return cls(J=J, C=scaled_inverse(J))

    @classmethod
    def from_covariance(cls, C: FloatArray) -> Bound:
        return cls(J=scaled_inverse(C), C=C)

    @property
    def trace(self) -> float:
        """tr(C): m^2 + (m/s)^2 as in the paper's objective."""
        return float(np.trace(self.C))

    @property
    def position_trace(self) -> float:
        """tr(C[:2, :2]) in m^2."""
        return float(np.trace(self.C[:2, :2]))

    @property
    def velocity_trace(self) -> float:
        """tr(C[2:, 2:]) in (m/s)^2."""
        return float(np.trace(self.C[2:, 2:]))


def _trace_inverse(J: FloatArray) -> FloatArray:
    """tr(J^-1) [L] for a batch J [L, 4, 4] (Jacobi-scaled); +inf where J is singular."""
    s = 1.0 / np.sqrt(np.einsum("lii->li", J))
    scaled = J * s[:, :, None] * s[:, None, :]
    out = np.full(J.shape[0], np.inf)
    ok = np.linalg.det(scaled) > 1e-300
    if np.any(ok):
        inv = np.linalg.inv(scaled[ok])
        out[ok] = np.einsum("lii,li->l", inv, s[ok] ** 2)
    return out


def predict_information(prev: Bound, F: FloatArray, W: FloatArray) -> FloatArray:
    """J_pred [4, 4] = (F J_{n-1}^-1 F^T + W)^-1: the prior information at slot n."""
    return scaled_inverse(F @ prev.C @ F.T + W)


def measurement_information(x: FloatArray, uav_xy: FloatArray, r_diag: FloatArray) -> FloatArray:
    """J_M [4, 4] = H^T R^-1 H (eq. 12) for variances r_diag [2M]; a non-finite variance (a
    measurement that did not arrive) contributes nothing."""
    g, k, _ = measurement_directions(x, uav_xy)
    H = np.vstack([g, k])
    with np.errstate(divide="ignore"):
        w = np.where(np.isfinite(r_diag), 1.0 / r_diag, 0.0)
    return np.asarray((H * w[:, None]).T @ H)


def bound_step(
    prev: Bound,
    F: FloatArray,
    W: FloatArray,
    x_pred: FloatArray,
    uav_xy: FloatArray,
    r_diag: FloatArray,
) -> Bound:
    """One step of the recursion: J_n = J_pred + H^T R^-1 H at the predicted state x_pred [4]."""
    J = predict_information(prev, F, W) + measurement_information(x_pred, uav_xy, r_diag)
    return Bound.from_information(0.5 * (J + J.T))


@dataclass(frozen=True)
class BoundAlong:
    """The bound's recursion along a plan of L slots (the receding horizon's objective):
    states [L, 4] (the predicted target at each slot), information [L, 4, 4] (J_l, symmetrised)
    and next_covariance [L, 4, 4] (P_l+1 = F J_l^-1 F^T + W, the next slot's predicted
    covariance with no measurement in between)."""

    states: FloatArray
    information: FloatArray
    next_covariance: FloatArray

    @property
    def traces(self) -> FloatArray:
        """tr(PCRB) [L]: tr(J_l^-1) at each slot."""
        return np.array([Bound.from_information(J).trace for J in self.information])


def bound_along(
    motion: MotionModel,
    dt_s: float,
    x_pred: FloatArray,
    J_pred: FloatArray,
    xy: FloatArray,
    eta: FloatArray,
    sensing: SensingParams,
    offsets: FloatArray | None = None,
) -> BoundAlong:
    """The recursion J_1 = J_pred + J_M,1, J_pred,l+1 = (F J_l^-1 F^T + W)^-1 along a plan xy
    [L, M, 2] (m), eta [L, M], every J_M at the target state the motion model predicts for its
    slot (x_1 = x_pred [4], x_l+1 = F x_l, steps of dt_s) plus its offset [L, 4] (m, m/s; None:
    none), a manoeuvring belief's departure from that straight path."""
    F, W = motion.transition(dt_s), motion.process_noise(dt_s)
    x = np.asarray(x_pred, dtype=float)
    prior = np.asarray(J_pred, dtype=float)
    L = len(xy)
    states, information, next_covariance = (
        np.empty((L, 4)),
        np.empty((L, 4, 4)),
        np.empty((L, 4, 4)),
    )
    for h in range(L):
        at = x if offsets is None else x + offsets[h]
        d = np.linalg.norm(at[None, :2] - xy[h], axis=1)
        J = prior + measurement_information(at, xy[h], sensing.variances(d, eta[h]))
        J = 0.5 * (J + J.T)
        P = F @ scaled_inverse(J) @ F.T + W
        states[h], information[h], next_covariance[h] = at, J, P
        prior = scaled_inverse(0.5 * (P + P.T))
        x = F @ x
    return BoundAlong(states, information, next_covariance)


@dataclass(frozen=True)
class PlanningObjective:
    """f(Q, eta) = tr((J_pred + J_M(Q, eta))^-1) at the predicted state (Section II-D).

    J_pred [4, 4]: prior information at this slot; x_pred [4]: predicted target state.
    measurement_only=True drops J_pred (the CRB-criterion benchmark: f = tr(J_M^-1)).
    """

    J_pred: FloatArray
    x_pred: FloatArray
    sensing: SensingParams
    measurement_only: bool = False

    def with_prior(self) -> PlanningObjective:
        """The objective with the prior information (the bound a plan reports, also for the
        CRB-criterion, which plans without it)."""
        return PlanningObjective(self.J_pred, self.x_pred, self.sensing)

    def _information(self, uav_xy: FloatArray, eta: FloatArray) -> tuple[FloatArray, ...]:
        g, k, d = measurement_directions(self.x_pred, uav_xy)
        a = self.sensing.range_information(d, eta)
        b = self.sensing.velocity_information(d)
        J = (g * a[:, None]).T @ g + (k * b[:, None]).T @ k
        if not self.measurement_only:
            J = J + self.J_pred
        return J, g, k, d, a, b

    def value(self, uav_xy: FloatArray, eta: FloatArray) -> float:
        """f for positions [M, 2] and shares [M]; +inf where J is singular (CRB-criterion)."""
        J = self._information(uav_xy, eta)[0]
        try:
            return float(np.trace(scaled_inverse(0.5 * (J + J.T))))
        except np.linalg.LinAlgError:
            return float("inf")

    def values(self, uav_xy: FloatArray, eta: FloatArray) -> FloatArray:
        """f for a batch: positions [L, M, 2] and shares [L, M] (or [M]) -> [L]."""
        J = self._batch_information(uav_xy, eta)
        if not self.measurement_only:
            J = J + self.J_pred[None]
        return _trace_inverse(J)

    def values_moving_one(
        self, current_xy: FloatArray, eta: FloatArray, m: int, candidates_m: FloatArray
    ) -> FloatArray:
        """f [L] of the plans `current_xy` [M, 2] with UAV m moved to candidates_m [L, 2], shares
        eta [M]: the other UAVs' information is summed once (J is additive over UAVs), so a batch
        costs one UAV's terms instead of M (equal to `values` up to summation round-off)."""
        rest = np.delete(np.arange(current_xy.shape[0]), m)
        # One call for both: rows 0..M-2 are the other UAVs' terms, the rest the candidates'.
        xy = np.concatenate([current_xy[rest], np.asarray(candidates_m)])[:, None, :]
        shares = np.concatenate([eta[rest], np.full(len(candidates_m), eta[m])])[:, None]
        terms = self._batch_information(xy, shares)
        J_rest = terms[: len(rest)].sum(axis=0)
        if not self.measurement_only:
            J_rest = J_rest + self.J_pred
        return _trace_inverse(J_rest[None] + terms[len(rest) :])

    def _batch_information(self, uav_xy: FloatArray, eta: FloatArray) -> FloatArray:
        """J_M [L, 4, 4] (measurements only) for positions [L, M, 2] and shares [L, M] or [M]."""
        x = self.x_pred
        r = x[None, None, :2] - uav_xy
        d = np.linalg.norm(r, axis=2)
        u = r / d[..., None]
        v_r = np.einsum("lmi,i->lm", u, x[2:])
        kp = (x[None, None, 2:] - v_r[..., None] * u) / d[..., None]
        eta_b = np.broadcast_to(eta, d.shape)
        a = self.sensing.range_information(d, eta_b)
        b = self.sensing.velocity_information(d)
        # Rows of H per UAV: g = (u, 0) and k = (kp, u); J = G^T diag(a) G + K^T diag(b) K.
        L, M = d.shape
        G = np.zeros((L, M, 4))
        G[..., :2] = u
        K = np.concatenate([kp, u], axis=2)
        J = np.matmul(np.swapaxes(G * a[..., None], 1, 2), G) + np.matmul(
            np.swapaxes(K * b[..., None], 1, 2), K
        )
        return np.asarray(J)

    def value_and_gradients(
        self, uav_xy: FloatArray, eta: FloatArray
    ) -> tuple[float, FloatArray, FloatArray]:
        """(f, df/dQ [M, 2] in m^2/m, df/deta [M]) by the analytic chain rule.

        d tr(J^-1) = -tr(C dJ C) with C = J^-1; dJ comes from the rank-one terms' derivatives with
        respect to r = p - q_m (then d/dq = -d/dr) and from a_m ∝ eta_m^2.
        """
        J, g, k, d, a, b = self._information(uav_xy, eta)
        C = scaled_inverse(0.5 * (J + J.T))
        C2 = C @ C
        x = self.x_pred
        w = x[2:]
        u = g[:, :2]
        kp = k[:, :2]
        v_r = u @ w
        perp = np.eye(2)[None] - u[:, :, None] * u[:, None, :]  # [M, 2, 2]
        m = uav_xy.shape[0]
        # dg/dr_j and dk/dr_j: [M, 2 (j), 4]
        dg = np.zeros((m, 2, 4))
        dg[:, :, :2] = perp / d[:, None, None]
        dk = np.zeros((m, 2, 4))
        inv_d = 1.0 / d
        dk[:, :, :2] = (
            -u[:, :, None] * w[None, None, :] * inv_d[:, None, None] ** 2
            - kp[:, :, None] * u[:, None, :] * inv_d[:, None, None]
            - v_r[:, None, None] * perp * inv_d[:, None, None] ** 2
            + v_r[:, None, None] * u[:, :, None] * u[:, None, :] * inv_d[:, None, None] ** 2
        )
        dk[:, :, 2:] = perp * inv_d[:, None, None]
        gC2g = np.einsum("mi,ij,mj->m", g, C2, g)
        kC2k = np.einsum("mi,ij,mj->m", k, C2, k)
        gC2dg = np.einsum("mi,ij,mrj->mr", g, C2, dg)
        kC2dk = np.einsum("mi,ij,mrj->mr", k, C2, dk)
        da = -4.0 * a[:, None] * u * inv_d[:, None]
        db = -4.0 * b[:, None] * u * inv_d[:, None]
        df_dr = -(
            da * gC2g[:, None]
            + 2 * a[:, None] * gC2dg
            + db * kC2k[:, None]
            + 2 * b[:, None] * kC2dk
        )
        grad_q = -df_dr
        grad_eta = -(2.0 * a / np.asarray(eta)) * gC2g
        return float(np.trace(C)), grad_q, grad_eta


@dataclass(frozen=True)
class SumObjective:
    """f(Q, eta) = sum_i w_i tr((J_pred,i + J_M,i(Q, eta))^-1): several targets' bounds, each
    weighted, each part a `PlanningObjective` at its own predicted state (docs/model.md,
    "Several targets"). weights: one per part (empty: all 1). The same methods as
    `PlanningObjective`, each the weighted sum of its parts' (the information of one target does
    not depend on another's, so the gradients add too)."""

    parts: tuple[PlanningObjective, ...]
    weights: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.weights and len(self.weights) != len(self.parts):
            raise ValueError(f"{len(self.weights)} weights for {len(self.parts)} targets")

    def _weighted(self) -> tuple[tuple[float, PlanningObjective], ...]:
        weights = self.weights or (1.0,) * len(self.parts)
        return tuple(zip(weights, self.parts, strict=True))

    def with_prior(self) -> SumObjective:
        """Every part with its prior information (`PlanningObjective.with_prior`)."""
        return SumObjective(tuple(p.with_prior() for p in self.parts), self.weights)

    def value(self, uav_xy: FloatArray, eta: FloatArray) -> float:
        """f for positions [M, 2] and shares [M]."""
        return float(sum(w * p.value(uav_xy, eta) for w, p in self._weighted()))

    def values(self, uav_xy: FloatArray, eta: FloatArray) -> FloatArray:
        """f [L] for positions [L, M, 2] and shares [L, M] (or [M])."""
        return np.asarray(sum(w * p.values(uav_xy, eta) for w, p in self._weighted()), dtype=float)

    def values_moving_one(
        self, current_xy: FloatArray, eta: FloatArray, m: int, candidates_m: FloatArray
    ) -> FloatArray:
        """f [L] with UAV m moved to candidates_m [L, 2] (`PlanningObjective.values_moving_one`)."""
        return np.asarray(
            sum(
                w * p.values_moving_one(current_xy, eta, m, candidates_m)
                for w, p in self._weighted()
            ),
            dtype=float,
        )

    def value_and_gradients(
        self, uav_xy: FloatArray, eta: FloatArray
    ) -> tuple[float, FloatArray, FloatArray]:
        """(f, df/dQ [M, 2], df/deta [M])."""
        f, grad_q, grad_eta = 0.0, np.zeros_like(uav_xy, dtype=float), np.zeros(len(eta))
        for w, p in self._weighted():
            fi, gq, ge = p.value_and_gradients(uav_xy, eta)
            f, grad_q, grad_eta = f + w * fi, grad_q + w * gq, grad_eta + w * ge
        return f, grad_q, grad_eta


Objective = PlanningObjective | SumObjective
"""What a slot problem minimises: one target's tr(PCRB), or several targets' sum."""
