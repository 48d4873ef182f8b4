"""Measurement-to-track association for one sensor's unlabelled report (docs/model.md, "Several
targets"): gating, global nearest neighbour (GNN) and joint probabilistic data association (JPDA),
and the PDA update that JPDA's marginals feed.

One UAV's report holds at most one measurement of each target plus false alarms, a Poisson
number with density lambda (per unit of the measurement space: per m * m/s for range and
Doppler). For track i with predicted measurement z_hat_i and innovation covariance S_i, and
measurement z_j, the likelihood ratio of "z_j is track i's" against "z_j is a false alarm" is

    l_ij = P_d N(z_j; z_hat_i, S_i) / lambda      (0 outside the gate d_ij^2 > gamma),

and a joint event theta (each track given at most one measurement, each measurement at most one
track) has the weight prod_{(i, j) in theta} l_ij * prod_{i missed} (1 - P_d P_g), P_g the gate
probability (Bar-Shalom, Willett and Tian, "Tracking and Data Fusion", 2011, ch. 6). GNN flies the
heaviest event (an assignment problem on -ln l_ij against -ln(1 - P_d P_g) for a miss, exact by
scipy's linear_sum_assignment); JPDA gives each track the marginals beta_ij over all events
(exact enumeration within each cluster of tracks that share gated measurements). Pure: numpy and
scipy. Shapes: T tracks, k measurements, d the measurement's dimension.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

from isac_mission.types import BoolArray, FloatArray, IntArray

MISSED = -1
"""The measurement index of a track given none."""


@functools.lru_cache(maxsize=256)
def gate_threshold(probability: float, dimension: int = 2) -> float:
    """gamma: the chi-square quantile with `dimension` degrees of freedom that a track's own
    measurement falls inside with `probability` (P_g); cached (the tracker asks it every slot)."""
    return float(chi2.ppf(probability, dimension))


@dataclass(frozen=True)
class Hypotheses:
    """One report against the tracks: likelihood_ratio [T, k] (l_ij, 0 outside the gate),
    gated [T, k], distance2 [T, k] (the Mahalanobis distances squared), miss_weight
    (1 - P_d P_g): one for every track, or [T] when each track has its own P_d."""

    likelihood_ratio: FloatArray
    gated: BoolArray
    distance2: FloatArray
    miss_weight: float | FloatArray

    def miss_weights(self) -> FloatArray:
        """[T] each track's 1 - P_d P_g."""
        return np.broadcast_to(np.asarray(self.miss_weight, dtype=float), self.gated.shape[:1])

    @classmethod
    def of(
        cls,
        predicted: FloatArray,
        innovation_cov: FloatArray,
        measurements: FloatArray,
        detection_prob: float | FloatArray,
        clutter_density: float,
        gate: float,
        gate_prob: float,
    ) -> Hypotheses:
        """predicted [T, d], innovation_cov [T, d, d], measurements [k, d]; detection_prob P_d,
        one for every track or [T]; clutter_density lambda > 0; gate gamma
        (`gate_threshold(gate_prob)`)."""
        z_hat = np.asarray(predicted, dtype=float)
        S = np.asarray(innovation_cov, dtype=float)
        dim = z_hat.shape[-1] if z_hat.ndim == 2 else 2
        z = np.asarray(measurements, dtype=float).reshape(-1, dim)
        T, k = len(z_hat), len(z)
        pd = np.broadcast_to(np.asarray(detection_prob, dtype=float), (T,))
        d2 = np.full((T, k), np.inf)
        ratio = np.zeros((T, k))
        for i in range(T if k else 0):
            nu = z - z_hat[i]
            d2[i] = np.einsum("kd,de,ke->k", nu, np.linalg.inv(S[i]), nu)
            norm = 1.0 / math.sqrt(float(np.linalg.det(2 * math.pi * S[i])))
            ratio[i] = pd[i] * norm * np.exp(-0.5 * d2[i]) / clutter_density
        gated = d2 <= gate
        ratio[~gated] = 0.0
        if np.ndim(detection_prob) == 0:
            return cls(ratio, gated, d2, 1.0 - float(detection_prob) * gate_prob)
        return cls(ratio, gated, d2, 1.0 - pd * gate_prob)


def gnn(h: Hypotheses) -> IntArray:
    """[T] the measurement index of each track in the heaviest joint event, or MISSED."""
    T, k = h.likelihood_ratio.shape
    out = np.full(T, MISSED, dtype=np.int64)
    if T == 0 or k == 0:
        return out
    big = 1e12
    with np.errstate(divide="ignore"):
        cost = np.where(h.gated, -np.log(h.likelihood_ratio), big)
    miss = np.full((T, T), big)
    w = h.miss_weights()
    with np.errstate(divide="ignore"):
        np.fill_diagonal(miss, np.where(w > 0, -np.log(np.where(w > 0, w, 1.0)), big))
    rows, cols = linear_sum_assignment(np.hstack([cost, miss]))
    for i, j in zip(rows, cols, strict=True):
        if j < k and h.gated[i, j] and cost[i, j] < big:
            out[i] = j
    return out


def clusters(gated: BoolArray) -> list[tuple[IntArray, IntArray]]:
    """The connected groups (tracks [.], measurements [.]) of the gate graph; a track with no
    gated measurement is a group of its own, a measurement gated by no track is in none."""
    T, k = gated.shape
    parent = list(range(T + k))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for i, j in zip(*np.nonzero(gated), strict=True):
        parent[find(int(i))] = find(T + int(j))
    groups: dict[int, tuple[list[int], list[int]]] = {}
    for node in range(T + k):
        tracks, meas = groups.setdefault(find(node), ([], []))
        (tracks if node < T else meas).append(node if node < T else node - T)
    return [
        (np.asarray(t, dtype=np.int64), np.asarray(m, dtype=np.int64))
        for t, m in groups.values()
        if t
    ]


def jpda(h: Hypotheses) -> FloatArray:
    """[T, k + 1] the marginal association probabilities: beta_ij for measurement j in column j,
    the miss beta_i0 in the last column; each row sums to 1. Exact: every joint event of each
    cluster enumerated."""
    T, k = h.likelihood_ratio.shape
    beta = np.zeros((T, k + 1))
    for tracks, meas in clusters(h.gated):
        sub = h.likelihood_ratio[np.ix_(tracks, meas)]
        weights = np.zeros((len(tracks), len(meas) + 1))
        total = _enumerate(sub, h.miss_weights()[tracks], weights)
        beta[tracks[:, None], meas[None]] = weights[:, :-1] / total
        beta[tracks, k] = weights[:, -1] / total
    return beta


def _enumerate(ratio: FloatArray, miss_weight: FloatArray, weights: FloatArray) -> float:
    """The sum of every joint event's weight over the tracks [t] and measurements [m] of
    `ratio` [t, m], track i missed with weight miss_weight [t], adding each event's weight into weights [t, m + 1] at the pairs it holds
    (the miss in the last column). Depth-first over the tracks."""
    t, m = ratio.shape
    chosen = [MISSED] * t
    used = np.zeros(m, dtype=bool)
    total = 0.0

    def visit(i: int, w: float) -> None:
        nonlocal total
        if w == 0.0:
            return
        if i == t:
            total += w
            for r, c in enumerate(chosen):
                weights[r, m if c == MISSED else c] += w
            return
        chosen[i] = MISSED
        visit(i + 1, w * float(miss_weight[i]))
        for j in np.flatnonzero((ratio[i] > 0) & ~used):
            used[j], chosen[i] = True, int(j)
            visit(i + 1, w * float(ratio[i, j]))
            used[j] = False
        chosen[i] = MISSED

    visit(0, 1.0)
    return total


def pda_update(
    x_pred: FloatArray,
    P_pred: FloatArray,
    predicted: FloatArray,
    H: FloatArray,
    S: FloatArray,
    measurements: FloatArray,
    beta: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """(x [n], P [n, n]): the PDA update of one track from its prediction x_pred [n], P_pred
    [n, n], predicted measurement [d], Jacobian H [d, n], innovation covariance S [d, d], the
    report's measurements [k, d] and its marginals beta [k + 1] (the miss last):

        x = x_pred + K nu,  nu = sum_j beta_j nu_j,  nu_j = z_j - z_hat,  K = P_pred H^T S^-1,
        P = beta_0 P_pred + (1 - beta_0)(I - K H) P_pred + K (sum_j beta_j nu_j nu_j^T - nu nu^T) K^T:

    the mean and covariance of the mixture of the miss (the prediction) and each measurement's
    EKF update; a one-hot beta is that EKF update (or the prediction)."""
    d = len(predicted)
    z = np.asarray(measurements, dtype=float).reshape(-1, d)
    b = np.asarray(beta, dtype=float)
    K = P_pred @ H.T @ np.linalg.inv(S)
    nu_j = z - predicted
    nu = b[:-1] @ nu_j if len(z) else np.zeros(d)
    spread = np.einsum("k,kd,ke->de", b[:-1], nu_j, nu_j) - np.outer(nu, nu)
    P_c = (np.eye(len(x_pred)) - K @ H) @ P_pred
    P = b[-1] * P_pred + (1 - b[-1]) * P_c + K @ spread @ K.T
    return np.asarray(x_pred + K @ nu), np.asarray(0.5 * (P + P.T))
