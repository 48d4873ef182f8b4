"""Exact checks of the original constraints (14a)-(14j) on candidate plans.

The SCA subproblem only approximates 14b, 14i and 14j; every plan the planner returns passes these
checks. Functions take batches: positions [L, M, 2], shares [L, M] -> [L] booleans.

With the safety rule on (planner.safety_margin, planning/margins.py; docs/model.md, "Safety")
14j keeps the slot's clearance from the predicted target, 14i keeps D_s + 2 e, 14a and 14b hold
e farther from the BS, and 14i/14j hold along the legs too (planning/legs.py); with "none" the
checks are the paper's. 14j holds against every target of the slot (the lead and
`other_targets`), each moving by its own motion model along the legs.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from isac_mission.config import Scenario
from isac_mission.model.channel import full_band_rate
from isac_mission.model.motion import MotionModel
from isac_mission.planning.legs import (
    chord_shortfall,
    leg_accel_bound_mps2,
    leg_fractions,
    sample_clearances_m,
    uav_leg_points,
)
from isac_mission.planning.margins import SafetyMargins, hermite_bulge_m, leg_samples, rule_on
from isac_mission.types import BoolArray, FloatArray, IntArray


@dataclass(frozen=True)
class MovingTargets:
    """Targets 14j keeps a clearance from, each moving by its own motion model.

    state [T, 4]: each one's predicted (x_m, y_m, vx_mps, vy_mps) at the slot's end;
    clearance_m [T]: the distance 14j keeps from each; motions: each one's motion model (T)."""

    state: FloatArray
    clearance_m: FloatArray
    motions: tuple[MotionModel, ...]

    def positions(self, before_end_s: FloatArray) -> FloatArray:
        """[T, S, 2] each target's predicted position before_end_s [S] (s, negative: before
        the slot's end) after the slot's end."""
        t = np.asarray(before_end_s, dtype=float).reshape(-1, 1)
        return np.stack(
            [
                np.asarray(m.position_after(x, t))
                for m, x in zip(self.motions, self.state, strict=True)
            ]
        )


@dataclass(frozen=True)
class SlotConstraints:
    """The data the constraints of one slot depend on.

    prev_xy [M, 2]: q_{n-1}; serving_bs_xy [M, 2]: w_{k_m} of the chosen association;
    bs_xy [K, 2]; target_xy [2]: predicted target position (14j); ballistic_xy [M, 2] and
    accel_radius_m: when set, the vehicle-dynamics limit ||q - ballistic|| <= radius;
    keep_out_xy [L, 2]: vehicles outside this plan (e.g. one whose link is lost and that holds
    where it is), from which every planned UAV keeps D_s as from another UAV (14i).
    target_clearance_m: the distance 14j keeps from the predicted target (safety.
    target_clearance_m; None: D_s); target_velocity_mps [2]: its predicted velocity, for the
    legs (None: at rest); start_velocity_mps [M, 2]: the vehicles' velocities at the legs'
    start, for Hermite legs (used with the end velocities given to `position_violations`).
    target_motion: the predicted target's motion model (None: the scenario's); other_targets:
    the slot's other targets (SlotInput.targets[1:]), from each of which 14j keeps its own
    clearance as from the predicted target, along the legs too, each moving by its own motion
    model (None: none).
    """

    prev_xy: FloatArray
    serving_bs_xy: FloatArray
    bs_xy: FloatArray
    target_xy: FloatArray
    scenario: Scenario
    ballistic_xy: FloatArray | None = None
    accel_radius_m: float = np.inf
    keep_out_xy: FloatArray | None = None
    target_clearance_m: float | None = None
    target_velocity_mps: FloatArray | None = None
    start_velocity_mps: FloatArray | None = None
    target_motion: MotionModel | None = None
    other_targets: MovingTargets | None = None

    @property
    def margins(self) -> SafetyMargins:
        """The scenario's fixed margins (planning/margins.py)."""
        return SafetyMargins.of(self.scenario)

    @property
    def clearance_m(self) -> float:
        """The distance 14j keeps from the predicted target, m."""
        c = self.target_clearance_m
        return self.scenario.d_safe if c is None else float(c)

    @property
    def separation_m(self) -> float:
        """The distance 14i keeps between UAVs and from keep-out points, m."""
        return self.margins.separation_m

    @property
    def leg_fractions(self) -> FloatArray:
        """tau_i [S] of the sampled leg instants ([1.0] with the rule off: the slot instant)."""
        return leg_fractions(leg_samples(self.scenario))

    @property
    def checks_legs(self) -> bool:
        """True when 14i/14j are checked along the legs (the rule on)."""
        return rule_on(self.scenario)

    @functools.cached_property
    def targets(self) -> MovingTargets:
        """Every target 14j keeps its clearance from [T]: the predicted target first (at rest
        without a velocity, by the scenario's motion model without its own), then
        other_targets."""
        v = np.zeros(2) if self.target_velocity_mps is None else self.target_velocity_mps
        state = np.concatenate([np.asarray(self.target_xy, dtype=float), np.asarray(v, float)])
        motion = self.scenario.motion if self.target_motion is None else self.target_motion
        lead = MovingTargets(state[None], np.array([self.clearance_m]), (motion,))
        o = self.other_targets
        if o is None or not len(o.motions):
            return lead
        return MovingTargets(
            np.concatenate([lead.state, np.asarray(o.state, dtype=float).reshape(-1, 4)]),
            np.concatenate([lead.clearance_m, np.asarray(o.clearance_m, dtype=float)]),
            lead.motions + tuple(o.motions),
        )

    def targets_points(self, fractions: FloatArray | None = None) -> FloatArray:
        """Every target [T, S, 2] at the leg samples tau_i dt (or at `fractions` [S]) of the
        slot ending at its prediction, each by its motion model."""
        f = self.leg_fractions if fractions is None else fractions
        return self.targets.positions(-((1.0 - np.asarray(f, dtype=float)) * self.scenario.dt))

    def targets_start(self) -> FloatArray:
        """Every target [T, 2] at the legs' start."""
        return self.targets.positions(np.array([-self.scenario.dt]))[:, 0]

    def target_points(self, fractions: FloatArray | None = None) -> FloatArray:
        """The predicted target [S, 2] at the leg samples (`targets_points` of the first)."""
        return np.asarray(self.targets_points(fractions)[0])

    def target_start(self) -> FloatArray:
        """The predicted target [2] at the legs' start."""
        return np.asarray(self.targets_start()[0])

    def sample_clearances_m(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(target [S, M], keep-out [S, M, K], pairs [S, P]): the distances the SCA subproblem
        and the polish keep at each leg sample (legs.sample_clearances_m, with the longest
        straight-leg chord between samples; pairs in np.triu_indices order). With the vehicle
        model's Hermite legs (`_legs`) each vehicle's distance grows by its bulge off the straight
        leg, at most (4/27) a_max dt^2 / 4, and the sagitta a_max h^2 / 8 (docs/model.md)."""
        s = self.scenario
        n = len(self.leg_fractions)
        h = s.dt / n
        bulge = 0.0
        if s.planner.vehicle_model and self.start_velocity_mps is not None:
            bulge = hermite_bulge_m(s.a_max, s.dt, h)
        v_t = self.target_velocity_mps
        speed_t = 0.0 if v_t is None else float(np.linalg.norm(v_t))
        prev = self.prev_xy
        start = np.linalg.norm(prev - self.target_start(), axis=-1)
        target = sample_clearances_m(self.clearance_m, start, (s.v_max + speed_t) * h, n)
        k = np.zeros((0, 2)) if self.keep_out_xy is None else np.asarray(self.keep_out_xy)
        start_k = np.linalg.norm(prev[:, None, :] - k[None], axis=-1)
        keep = sample_clearances_m(self.separation_m, start_k, s.v_max * h, n)
        i, j = _pairs(s.M)
        start_p = np.linalg.norm(prev[i] - prev[j], axis=-1)
        pairs = sample_clearances_m(self.separation_m, start_p, 2 * s.v_max * h, n)
        return target + bulge, keep + bulge, pairs + 2 * bulge

    def area_bounds(self) -> tuple[FloatArray, FloatArray]:
        """operating_area(scenario)."""
        return operating_area(self.scenario)

    def full_rates(self, uav_xy: FloatArray) -> FloatArray:
        """R~ [..., M] of each UAV on its serving BS, bit/s (e = margins.link_m farther away)."""
        s = self.scenario
        dist = np.linalg.norm(uav_xy - self.serving_bs_xy, axis=-1)
        e = self.margins.link_m
        return np.asarray(full_band_rate(dist + e if e else dist, s.dH, s.rho0, s.B))

    def position_violations(
        self,
        uav_xy: FloatArray,
        tol_m: float = 0.0,
        end_velocity_mps: FloatArray | None = None,
    ) -> dict[str, BoolArray]:
        """Per constraint, [L] True where positions [L, M, 2] violate 14b, 14h, 14i or 14j.
        end_velocity_mps [L, M, 2] or [M, 2]: the planned end velocities (Hermite legs, with
        start_velocity_mps); None: straight legs."""
        s = self.scenario
        q = np.asarray(uav_xy).reshape(-1, s.M, 2)
        nearest_bs = np.sqrt(np.min(_sq_norm(q[:, :, None, :] - self.bs_xy[None, None]), axis=2))
        step = np.sqrt(_sq_norm(q - self.prev_xy[None]))
        targets = self.targets
        to_target = np.sqrt(_sq_norm(q[:, :, None, :] - targets.state[None, None, :, :2]))
        sep, link = self.separation_m, self.margins.link_m
        out = {
            "14b control range": np.any(nearest_bs + link > s.d_th + tol_m, axis=1),
            "14h max speed": np.any(step > s.v_max * s.dt + tol_m, axis=1),
            "14j target distance": np.any(to_target < targets.clearance_m - tol_m, axis=(1, 2)),
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
            out["14i UAV separation"] = np.any(gaps < sep - tol_m, axis=1)
        if self.keep_out_xy is not None and len(self.keep_out_xy):
            gaps = np.sqrt(_sq_norm(q[:, :, None, :] - self.keep_out_xy[None, None]))
            out["14i separation from unplanned UAVs"] = np.any(gaps < sep - tol_m, axis=(1, 2))
        if self.checks_legs:
            out.update(self._leg_violations(q, tol_m, end_velocity_mps))
        return out

    def _legs(
        self, prev: FloatArray, end: FloatArray, idx: list[int] | slice, v1: FloatArray | None
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(positions [..., S, M', 2], largest acceleration [..., M'], fractions [S]) of the legs
        prev [M', 2] -> end [..., M', 2] of the UAVs idx: Hermite legs from start_velocity_mps
        to v1 when v1 is given, or to the mean velocity (end - prev) / dt with
        planner.vehicle_model (the leg the bridge flies, model/vehicle.py), at the leg samples;
        straight legs otherwise, at their end only: against the constant-velocity target and
        each other they move linearly, so the one chord r(0) -> r(dt) is the exact check."""
        s = self.scenario
        v0 = None if self.start_velocity_mps is None else np.asarray(self.start_velocity_mps)[idx]
        if v1 is None and v0 is not None and s.planner.vehicle_model:
            v1 = (np.asarray(end) - prev) / s.dt
        if v1 is None or v0 is None:
            v0 = v1 = None
        fractions = self.leg_fractions if v0 is not None else np.ones(1)
        pts = uav_leg_points(prev, end, fractions, s.dt, v0, v1)
        return pts, leg_accel_bound_mps2(prev, end, s.dt, v0, v1), fractions

    def _leg_violations(
        self, q: FloatArray, tol_m: float, end_velocity_mps: FloatArray | None
    ) -> dict[str, BoolArray]:
        """14j and 14i along the legs prev_xy -> q [L, M, 2] (planning/legs.py)."""
        s = self.scenario
        pts, accel, fractions = self._legs(self.prev_xy, q, slice(None), end_velocity_mps)
        h = s.dt / len(fractions)  # accel [L, M]
        targets = self.targets
        rel = pts[:, None] - self.targets_points(fractions)[None, :, :, None, :]  # [L, T, S, M, 2]
        rel0 = self.prev_xy[None] - self.targets_start()[:, None]  # [T, M, 2]
        short = chord_shortfall(
            np.broadcast_to(rel0, (len(q), *rel0.shape)),
            np.moveaxis(rel, 2, 3),
            targets.clearance_m[None, :, None],
            (accel * h**2 / 8)[:, None, :],
        )  # [L, T, M]
        out = {"14j along the legs": np.any(short > tol_m, axis=(1, 2))}
        sep = self.separation_m
        if s.M > 1:
            i, j = _pairs(s.M)
            rel = np.moveaxis(pts[:, :, i] - pts[:, :, j], 1, 2)  # [L, P, S, 2]
            rel0 = np.broadcast_to(self.prev_xy[i] - self.prev_xy[j], (*rel.shape[:2], 2))
            sag = (accel[:, i] + accel[:, j]) * h**2 / 8
            short = chord_shortfall(rel0, rel, sep, sag)
            out["14i along the legs"] = np.any(short > tol_m, axis=1)
        if self.keep_out_xy is not None and len(self.keep_out_xy):
            k = self.keep_out_xy
            rel = pts[:, :, :, None, :] - k[None, None, None]  # [L, S, M, K, 2]
            rel = np.moveaxis(rel, 1, 3)  # [L, M, K, S, 2]
            rel0 = np.broadcast_to((self.prev_xy[:, None] - k[None])[None], (*rel.shape[:3], 2))
            sag = (accel * h**2 / 8)[:, :, None]
            short = chord_shortfall(rel0, rel, sep, sag)
            out["14i along the legs (unplanned UAVs)"] = np.any(short > tol_m, axis=(1, 2))
        return out

    def rate_violations(self, uav_xy: FloatArray, eta: FloatArray) -> BoolArray:
        """[L] True where some UAV's rate eta R~ is below R_th (14a), relative tolerance 1e-12."""
        s = self.scenario
        rates = np.asarray(eta) * self.full_rates(np.asarray(uav_xy).reshape(-1, s.M, 2))
        return np.asarray(np.any(rates < s.r_th * (1 - 1e-12), axis=-1))

    def feasible(
        self,
        uav_xy: FloatArray,
        eta: FloatArray,
        tol_m: float = 0.0,
        end_velocity_mps: FloatArray | None = None,
    ) -> BoolArray:
        """[L] True where (positions, shares) satisfy 14a-14j (14c/14d hold by construction);
        end_velocity_mps as in `position_violations`."""
        bad = self.rate_violations(uav_xy, eta)
        for v in self.position_violations(uav_xy, tol_m, end_velocity_mps).values():
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
        sep = self.separation_m
        bad = eta[m] * self.full_rates_one(q, m) < s.r_th * (1 - 1e-12)
        nearest_bs = np.sqrt(np.min(_sq_norm(q[:, None, :] - self.bs_xy[None]), axis=1))
        bad |= nearest_bs + self.margins.link_m > s.d_th
        bad |= np.sqrt(_sq_norm(q - self.prev_xy[m])) > s.v_max * s.dt
        targets = self.targets
        to_target = np.sqrt(_sq_norm(q[:, None, :] - targets.state[None, :, :2]))  # [L, T]
        bad |= np.any(to_target < targets.clearance_m, axis=1)
        if s.planner.keep_in_area:
            lo, hi = self.area_bounds()
            bad |= np.any((q < lo) | (q > hi), axis=-1)
        if self.ballistic_xy is not None:
            bad |= np.sqrt(_sq_norm(q - self.ballistic_xy[m])) > self.accel_radius_m
        others = np.delete(current_xy, m, axis=0)
        if s.M > 1:
            gaps = np.sqrt(_sq_norm(q[:, None, :] - others[None]))
            bad |= np.any(gaps < sep, axis=1)
        if self.keep_out_xy is not None and len(self.keep_out_xy):
            gaps = np.sqrt(_sq_norm(q[:, None, :] - self.keep_out_xy[None]))
            bad |= np.any(gaps < sep, axis=1)
        if self.checks_legs:
            bad |= self._leg_violations_moving_one(current_xy, m, q)
        return np.asarray(~bad)

    def _leg_violations_moving_one(
        self, current_xy: FloatArray, m: int, q: FloatArray
    ) -> BoolArray:
        """[L] True where UAV m's leg prev_m -> q [L, 2] breaks 14j or 14i along the legs (the
        others on their legs to current_xy; the legs as `_legs`)."""
        s = self.scenario
        prev = self.prev_xy[m]
        pts_m, acc_m, fractions = self._legs(self.prev_xy[[m]], q[:, None, :], [m], None)
        h = s.dt / len(fractions)
        pts, sag = pts_m[:, :, 0], acc_m[:, 0] * h**2 / 8  # [L, S, 2], [L]
        rel = pts[:, None] - self.targets_points(fractions)[None]  # [L, T, S, 2]
        rel0 = np.broadcast_to(prev - self.targets_start(), (len(q), *rel.shape[1:2], 2))
        clearance = self.targets.clearance_m[None]
        bad = np.any(chord_shortfall(rel0, rel, clearance, sag[:, None]) > 0, axis=1)
        sep = self.separation_m
        idx = [j for j in range(s.M) if j != m]
        if idx:
            o_pts, o_acc, _ = self._legs(self.prev_xy[idx], current_xy[idx], idx, None)
            rel = np.moveaxis(pts[:, :, None, :] - o_pts[None], 1, 2)  # [L, O, S, 2]
            rel0 = np.broadcast_to(prev - self.prev_xy[idx], (*rel.shape[:2], 2))
            o_sag = sag[:, None] + o_acc[None] * h**2 / 8
            bad |= np.any(chord_shortfall(rel0, rel, sep, o_sag) > 0, axis=1)
        if self.keep_out_xy is not None and len(self.keep_out_xy):
            k = self.keep_out_xy
            rel = np.moveaxis(pts[:, :, None, :] - k[None, None], 1, 2)  # [L, K, S, 2]
            rel0 = np.broadcast_to(prev - k, (*rel.shape[:2], 2))
            bad |= np.any(chord_shortfall(rel0, rel, sep, sag[:, None]) > 0, axis=1)
        return np.asarray(bad)

    def full_rates_one(self, uav_xy_m: FloatArray, m: int) -> FloatArray:
        """R~ [L] of UAV m at positions uav_xy_m [L, 2] on its serving BS, bit/s (as
        `full_rates`)."""
        s = self.scenario
        dist = np.linalg.norm(uav_xy_m - self.serving_bs_xy[m], axis=-1)
        e = self.margins.link_m
        return np.asarray(full_band_rate(dist + e if e else dist, s.dH, s.rho0, s.B))

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
