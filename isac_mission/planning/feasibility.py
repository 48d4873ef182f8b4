"""Exact checks of the original constraints (14a)-(14j) on candidate plans.

The SCA subproblem only approximates 14b, 14i and 14j; every plan the planner returns passes these
checks. Functions take batches: positions [L, M, 2], shares [L, M] -> [L] booleans.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.channel import full_band_rate
from isac_mission.types import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class SlotConstraints:
    """The data the constraints of one slot depend on.

    prev_xy [M, 2]: q_{n-1}; serving_bs_xy [M, 2]: w_{k_m} of the chosen association;
    bs_xy [K, 2]; target_xy [2]: predicted target position (14j); ballistic_xy [M, 2] and
    accel_radius_m: when set, the vehicle-dynamics limit ||q - ballistic|| <= radius;
    keep_out_xy [L, 2]: vehicles outside this plan (e.g. one whose link is lost and that holds
    where it is), from which every planned UAV keeps D_s as from another UAV (14i).
    """

    prev_xy: FloatArray
    serving_bs_xy: FloatArray
    bs_xy: FloatArray
    target_xy: FloatArray
    scenario: Scenario
    ballistic_xy: FloatArray | None = None
    accel_radius_m: float = np.inf
    keep_out_xy: FloatArray | None = None

    def area_bounds(self) -> tuple[FloatArray, FloatArray]:
        """operating_area(scenario)."""
        return operating_area(self.scenario)

    def full_rates(self, uav_xy: FloatArray) -> FloatArray:
        """R~ [..., M] of each UAV on its serving BS, bit/s."""
        s = self.scenario
        dist = np.linalg.norm(uav_xy - self.serving_bs_xy, axis=-1)
        return np.asarray(full_band_rate(dist, s.dH, s.rho0, s.B))

    def position_violations(self, uav_xy: FloatArray, tol_m: float = 0.0) -> dict[str, BoolArray]:
        """Per constraint, [L] True where positions [L, M, 2] violate 14b, 14h, 14i or 14j."""
        s = self.scenario
        q = np.asarray(uav_xy).reshape(-1, s.M, 2)
        nearest_bs = np.sqrt(np.min(_sq_norm(q[:, :, None, :] - self.bs_xy[None, None]), axis=2))
        step = np.sqrt(_sq_norm(q - self.prev_xy[None]))
        to_target = np.sqrt(_sq_norm(q - self.target_xy[None, None]))
        out = {
            "14b control range": np.any(nearest_bs > s.d_th + tol_m, axis=1),
            "14h max speed": np.any(step > s.v_max * s.dt + tol_m, axis=1),
            "14j target distance": np.any(to_target < s.d_safe - tol_m, axis=1),
        }
        if s.planner.keep_in_area:
            lo, hi = self.area_bounds()
            outside = np.any((q < lo - tol_m) | (q > hi + tol_m), axis=-1)
            out["operating area"] = np.any(outside, axis=1)
        if self.ballistic_xy is not None:
            off = np.linalg.norm(q - self.ballistic_xy[None], axis=-1)
            out["vehicle acceleration"] = np.any(off > self.accel_radius_m + tol_m, axis=1)
        if s.M > 1:
            i, j = _pairs(s.M)
            gaps = np.sqrt(_sq_norm(q[:, i] - q[:, j]))
            out["14i UAV separation"] = np.any(gaps < s.d_safe - tol_m, axis=1)
        if self.keep_out_xy is not None and len(self.keep_out_xy):
            gaps = np.sqrt(_sq_norm(q[:, :, None, :] - self.keep_out_xy[None, None]))
            out["14i separation from unplanned UAVs"] = np.any(gaps < s.d_safe - tol_m, axis=(1, 2))
        return out

    def rate_violations(self, uav_xy: FloatArray, eta: FloatArray) -> BoolArray:
        """[L] True where some UAV's rate eta R~ is below R_th (14a), relative tolerance 1e-12."""
        s = self.scenario
        rates = np.asarray(eta) * self.full_rates(np.asarray(uav_xy).reshape(-1, s.M, 2))
        return np.asarray(np.any(rates < s.r_th * (1 - 1e-12), axis=-1))

    def feasible(self, uav_xy: FloatArray, eta: FloatArray, tol_m: float = 0.0) -> BoolArray:
        """[L] True where (positions, shares) satisfy 14a-14j (14c/14d hold by construction)."""
        bad = self.rate_violations(uav_xy, eta)
        for v in self.position_violations(uav_xy, tol_m).values():
            bad = bad | v
        return np.asarray(~bad)

    def feasible_moving_one(
        self, current_xy: FloatArray, eta: FloatArray, m: int, candidates_m: FloatArray
    ) -> BoolArray:
        """[L] feasibility of the plans `current_xy` [M, 2] with UAV m moved to candidates_m
        [L, 2], shares eta [M], given that `current_xy` itself is feasible: only the constraints
        that involve UAV m can change, so only those are checked (the same answer as `feasible`
        on the full plans, at 1/M of the cost)."""
        s = self.scenario
        q = np.asarray(candidates_m, dtype=float)
        bad = eta[m] * self.full_rates_one(q, m) < s.r_th * (1 - 1e-12)
        nearest_bs = np.sqrt(np.min(_sq_norm(q[:, None, :] - self.bs_xy[None]), axis=1))
        bad |= nearest_bs > s.d_th
        bad |= np.sqrt(_sq_norm(q - self.prev_xy[m])) > s.v_max * s.dt
        bad |= np.sqrt(_sq_norm(q - self.target_xy)) < s.d_safe
        if s.planner.keep_in_area:
            lo, hi = self.area_bounds()
            bad |= np.any((q < lo) | (q > hi), axis=-1)
        if self.ballistic_xy is not None:
            bad |= np.sqrt(_sq_norm(q - self.ballistic_xy[m])) > self.accel_radius_m
        if s.M > 1:
            others = np.delete(current_xy, m, axis=0)
            gaps = np.sqrt(_sq_norm(q[:, None, :] - others[None]))
            bad |= np.any(gaps < s.d_safe, axis=1)
        if self.keep_out_xy is not None and len(self.keep_out_xy):
            gaps = np.sqrt(_sq_norm(q[:, None, :] - self.keep_out_xy[None]))
            bad |= np.any(gaps < s.d_safe, axis=1)
        return np.asarray(~bad)

    def full_rates_one(self, uav_xy_m: FloatArray, m: int) -> FloatArray:
        """R~ [L] of UAV m at positions uav_xy_m [L, 2] on its serving BS, bit/s."""
        s = self.scenario
        dist = np.linalg.norm(uav_xy_m - self.serving_bs_xy[m], axis=-1)
        return np.asarray(full_band_rate(dist, s.dH, s.rho0, s.B))

    def describe_violations(self, uav_xy: FloatArray, eta: FloatArray) -> list[str]:
        """Names of the constraints one plan (uav_xy [M, 2], eta [M]) violates."""
        names = [k for k, v in self.position_violations(uav_xy).items() if bool(v[0])]
        if bool(self.rate_violations(uav_xy, eta)[0]):
            names.insert(0, "14a rate")
        if abs(float(np.sum(eta)) - 1.0) > 1e-9 or np.any(np.asarray(eta) < 0):
            names.append("14c/14d shares")
        return names


def operating_area(s: Scenario) -> tuple[FloatArray, FloatArray]:
    """(lower [2], upper [2]) corners of the box every UAV stays in, m: the operating area when
    planner.keep_in_area is set, else unbounded."""
    if not s.planner.keep_in_area:
        return np.full(2, -np.inf), np.full(2, np.inf)
    return np.zeros(2), np.asarray(s.area, dtype=float)


def _sq_norm(v: FloatArray) -> FloatArray:
    """Squared Euclidean norm over the last axis of length 2 (as np.linalg.norm sums it)."""
    return np.asarray(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])


@functools.lru_cache(maxsize=64)
def _pairs(n: int) -> tuple[IntArray, IntArray]:
    """The index pairs i < j of n UAVs (cached: every feasibility check needs them)."""
    i, j = np.triu_indices(n, 1)
    return np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)


def capacity_ok(bs_of_uav: IntArray, n_bs: int, capacity: int) -> bool:
    """14e-14g: every UAV on one valid BS, at most N_a UAVs per BS."""
    if np.any(bs_of_uav < 0) or np.any(bs_of_uav >= n_bs):
        return False
    return bool(np.bincount(bs_of_uav, minlength=n_bs).max() <= capacity)
