"""The communication-optimal plan (Section III-A): Lemma 1 shares and the fly-to-BS trajectory.

It decides feasibility (P1 is feasible only if R_c* >= R_th) and is the best-effort fallback of an
infeasible slot, since it maximises the worst UAV's rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.model.channel import full_band_rate
from isac_mission.types import FloatArray


@dataclass(frozen=True)
class CommunicationPlan:
    """uav_xy [M, 2] waypoints, eta [M] Lemma 1 shares, worst_rate_bps = R_c*."""

    uav_xy: FloatArray
    eta: FloatArray
    worst_rate_bps: float


def lemma1_shares(full_rates_bps: FloatArray) -> FloatArray:
    """eta_m = (1 / R~_m) / sum_j (1 / R~_j): equal rates for all UAVs (Lemma 1); [M]."""
    inv = 1.0 / np.asarray(full_rates_bps)
    return np.asarray(inv / inv.sum())


def fly_towards(prev_xy: FloatArray, goal_xy: FloatArray, max_step_m: float) -> FloatArray:
    """Each row of prev_xy [M, 2] moved toward goal_xy [M, 2] by at most max_step_m (eq. 18)."""
    delta = goal_xy - prev_xy
    dist = np.linalg.norm(delta, axis=1, keepdims=True)
    # A hair short of the full step, so round-off never puts the waypoint beyond V_max dt.
    scale = np.minimum(1.0, max_step_m * (1 - 1e-12) / np.maximum(dist, 1e-12))
    return np.asarray(prev_xy + scale * delta)


def communication_optimal(
    prev_xy: FloatArray,
    serving_bs_xy: FloatArray,
    *,
    max_step_m: float,
    dH: float,
    rho0: float,
    B: float,
) -> CommunicationPlan:
    """Fly at full speed toward the serving BS (serving_bs_xy [M, 2]) and share by Lemma 1."""
    xy = fly_towards(prev_xy, serving_bs_xy, max_step_m)
    rates = full_band_rate(np.linalg.norm(xy - serving_bs_xy, axis=1), dH, rho0, B)
    eta = lemma1_shares(rates)
    return CommunicationPlan(uav_xy=xy, eta=eta, worst_rate_bps=float(1.0 / np.sum(1.0 / rates)))
