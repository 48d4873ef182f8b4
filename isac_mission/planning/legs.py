"""Safety distances along the legs between slot instants (docs/model.md, "Safety").

A leg runs from q_{n-1} (time 0) to q_n (time dt): straight at constant velocity with the
paper's kinematics, or the cubic Hermite leg of model/vehicle.py when its end velocities are
given. The target follows its constant-velocity prediction, p(tau) = p_pred - (1 - tau) dt v_pred.
The distances are kept at the samples tau_i = i / S (i = 1..S, S = planner.horizon.leg_samples)
and on the chords between them: the relative motion r(tau) between two samples h = dt / S apart
stays within a_rel h^2 / 8 of its chord (the sagitta bound, a_rel the largest relative
acceleration), so a chord that keeps c + a_rel h^2 / 8 from the other party keeps the curve at c.
Straight legs against a constant-velocity target move linearly relative to each other (a_rel = 0):
the check is exact. The leg starts where the last one ended, which this plan cannot change: a
chord keeps c' = min(c, |r(0)|) (a vehicle that starts inside the clearance, because the
clearance grew or the estimate moved, never comes closer on its way out), and the leg's end keeps
c itself (14i, 14j at the slot instant).

Pure: numpy only. Shapes: M UAVs, S samples, any leading batch shape [...].
"""

from __future__ import annotations

import numpy as np

from isac_mission.model.vehicle import end_accelerations, hermite_position
from isac_mission.types import FloatArray


def leg_fractions(n_samples: int) -> FloatArray:
    """tau_i = i / S, i = 1..S [S]: the sampled instants of a leg, as fractions of dt."""
    return np.arange(1, n_samples + 1, dtype=float) / n_samples


def uav_leg_points(
    prev_xy: FloatArray,
    end_xy: FloatArray,
    fractions: FloatArray,
    dt_s: float,
    start_velocity_mps: FloatArray | None = None,
    end_velocity_mps: FloatArray | None = None,
) -> FloatArray:
    """Positions [..., S, M, 2] on the legs prev_xy [M, 2] -> end_xy [..., M, 2] at fractions
    [S]: straight (constant velocity) unless both velocities [M, 2] (or [..., M, 2]) are given,
    then the Hermite leg."""
    end = np.asarray(end_xy, dtype=float)
    tau = np.asarray(fractions, dtype=float).reshape((-1, 1, 1))
    if start_velocity_mps is None or end_velocity_mps is None:
        return np.asarray(prev_xy + tau * (end[..., None, :, :] - prev_xy))
    v0 = np.asarray(start_velocity_mps, dtype=float)
    v1 = np.asarray(end_velocity_mps, dtype=float)
    points = [hermite_position(prev_xy, v0, end, v1, dt_s, float(f)) for f in fractions]
    return np.asarray(np.stack(np.broadcast_arrays(*points), axis=-3))


def leg_accel_bound_mps2(
    prev_xy: FloatArray,
    end_xy: FloatArray,
    dt_s: float,
    start_velocity_mps: FloatArray | None = None,
    end_velocity_mps: FloatArray | None = None,
) -> FloatArray:
    """The largest acceleration norm [..., M] on each leg (m/s^2): 0 on a straight leg, else
    max(|a(0)|, |a(dt)|) (exact on a cubic, model/vehicle.py)."""
    end = np.asarray(end_xy, dtype=float)
    if start_velocity_mps is None or end_velocity_mps is None:
        return np.zeros(end.shape[:-1])
    a0, a1 = end_accelerations(prev_xy, start_velocity_mps, end, end_velocity_mps, dt_s)
    return np.asarray(np.maximum(np.linalg.norm(a0, axis=-1), np.linalg.norm(a1, axis=-1)))


def segment_distance(a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance [...] from the origin to the segments a -> b ([..., 2] each)."""
    d = b - a
    dd = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]
    t = -(a[..., 0] * d[..., 0] + a[..., 1] * d[..., 1]) / np.where(dd > 0, dd, 1.0)
    t = np.clip(np.where(dd > 0, t, 0.0), 0.0, 1.0)
    x, y = a[..., 0] + t * d[..., 0], a[..., 1] + t * d[..., 1]
    return np.asarray(np.sqrt(x * x + y * y))


def closest_on_legs(relative_start: FloatArray, relative: FloatArray) -> FloatArray:
    """[..., S] distance from the origin to each chord of the relative motion: chord 0 from
    relative_start [..., 2] (tau = 0) to relative[..., 0, :], chord i from sample i - 1 to
    sample i (relative [..., S, 2])."""
    starts = np.concatenate([np.asarray(relative_start)[..., None, :], relative[..., :-1, :]], -2)
    return segment_distance(starts, relative)


def chord_shortfall(
    relative_start: FloatArray,
    relative: FloatArray,
    clearance_m: float | FloatArray,
    sagitta_m: float | FloatArray = 0.0,
) -> FloatArray:
    """[...] how far (m, > 0 = violated) the relative motion comes inside clearance_m: each chord
    must keep min(clearance, |r(0)|) + sagitta.

    relative_start [..., 2]: r(0); relative [..., S, 2]: r(tau_i); clearance_m and sagitta_m
    broadcast against [...]."""
    dist = closest_on_legs(relative_start, relative)
    c = np.asarray(clearance_m, dtype=float)[..., None]
    sag = np.asarray(sagitta_m, dtype=float)[..., None]
    start = np.linalg.norm(relative_start, axis=-1)[..., None]
    return np.asarray(np.max(np.minimum(c, start) + sag - dist, axis=-1))


def chord_point_clearance_m(clearance_m: float | FloatArray, chord_m: float) -> FloatArray:
    """The distance (m) two ends of a chord of length chord_m must keep so that the whole chord
    keeps clearance_m: sqrt(c^2 + (chord / 2)^2) (the chord's midpoint is nearest at worst)."""
    return np.asarray(np.hypot(clearance_m, 0.5 * chord_m))


def sample_clearances_m(
    clearance_m: float, start_distance_m: FloatArray, chord_m: float, n_samples: int
) -> FloatArray:
    """[S, ...] the distance each leg sample keeps in the SCA subproblem and the polish so that
    the chords keep c' = min(c, |r(0)|) (start_distance_m [...]) and the end keeps c:
    chord_point_clearance_m(c', chord) at every sample, and at least c at the last."""
    c1 = np.minimum(clearance_m, np.asarray(start_distance_m, dtype=float))
    rows = np.repeat(chord_point_clearance_m(c1, chord_m)[None], n_samples, axis=0)
    rows[-1] = np.maximum(rows[-1], clearance_m)
    return np.asarray(rows)
