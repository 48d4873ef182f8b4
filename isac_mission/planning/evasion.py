"""Evasion under the vehicle model: which vehicles are in danger, and the legs that pull them apart.

A plan that meets 14i at the end of its slot can still leave two UAVs closing faster than they
can brake apart before D_s: the per-slot plan's mean-velocity legs change a velocity by at most
a_max dt / 4 a slot (model/vehicle.py), and it looks one slot ahead. Two tests find the danger
(docs/model.md, "Evasion"):

- `coasting_threats`: at the start of a slot, the parties (the UAVs, the target at its predicted
  velocity, the keep-out points still) coast; a UAV is threatened by a party it would come within
  its clearance of within the look-ahead (dt plus the time to cancel their relative velocity at
  a_max). The best effort of an infeasible slot evades these.
- `unviable_pairs`: at the end of a planned slot, a UAV pair closing at c with its gap g beyond the
  separation d is viable if g - d >= c^2 / (4 a_max): both braking along their line of sight at
  a_max (2 a_max relative) they stop closing before d. A keep-out point (a vehicle holding) is
  viable from a UAV if g - d >= c^2 / (2 a_max). A plan with an unviable pair is replaced on those
  UAVs by the evasive legs (planning/slot.py): braking from a viable start keeps the pair apart.

`evasive_legs` gives each threatened UAV the constant-acceleration leg that accelerates as far as
a_max and V_max allow (`evasive_velocity`) along the sum of the directions away from its threats
now, each weighted by 1 / max(time to the closest approach, dt), or, where that sum points toward
one of them, along the direction that moves it away from all of them the most (`away_from_all`):
p1 = p0 + (v0 + v1) dt / 2, the parabola a cubic Hermite leg with these ends is (|a| <= a_max all
along it, its speed largest at an end, <= V_max). Pushing along the miss vector instead, which
grows the miss distance faster in theory, lost to V_max on the measured M = 12 trap (27.7 m of
D_s = 30; docs/model.md, "Evasion under the vehicle model").

The target cannot be outbraked when it is faster than V_max, but it can be dodged:
`target_escape` asks whether a UAV can still keep the clearance from every target motion within
its manoeuvre bound a_T by coasting or by accelerating along one of three directions; a plan's end
state that cannot is replaced by the evasive leg along the best of them (docs/model.md, "Evasion").

Pure: numpy only. Shapes: M UAVs, P parties (M UAVs, the target, K keep-out points).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from isac_mission.types import BoolArray, FloatArray

VIABILITY_TOL_M = 1e-6
"""Slack (m) of the viability test, so that a pair braked exactly to its limit stays viable."""


@dataclass(frozen=True)
class Parties:
    """What a UAV keeps its distance from, at the start of a slot: xy_m [P, 2] (m), velocity_mps
    [P, 2] (m/s), clearance_m [P] (m), braking [P] (True where the party brakes too: the other
    UAVs); rows 0..M-1 are the UAVs themselves, then the target, then the keep-out points."""

    xy_m: FloatArray
    velocity_mps: FloatArray
    clearance_m: FloatArray
    braking: BoolArray

    @classmethod
    def of(
        cls,
        uav_xy_m: FloatArray,
        uav_velocity_mps: FloatArray,
        separation_m: float,
        target_xy_m: FloatArray,
        target_velocity_mps: FloatArray,
        target_clearance_m: float,
        keep_out_xy_m: FloatArray | None,
    ) -> Parties:
        """The UAVs [M, 2] at their velocities [M, 2] (separation_m apart), the target [2] at its
        velocity [2] (target_clearance_m) and the keep-out points [K, 2] still (separation_m)."""
        keep = np.zeros((0, 2)) if keep_out_xy_m is None else np.asarray(keep_out_xy_m, float)
        M = len(uav_xy_m)
        return cls(
            xy_m=np.vstack([uav_xy_m, np.reshape(target_xy_m, (1, 2)), keep]),
            velocity_mps=np.vstack(
                [uav_velocity_mps, np.reshape(target_velocity_mps, (1, 2)), np.zeros_like(keep)]
            ),
            clearance_m=np.r_[
                np.full(M, separation_m), target_clearance_m, np.full(len(keep), separation_m)
            ],
            braking=np.r_[np.ones(M, bool), False, np.zeros(len(keep), bool)],
        )

    def relative_to(
        self, uav_xy_m: FloatArray, uav_velocity_mps: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """(positions [M, P, 2], velocities [M, P, 2]) of UAVs at uav_xy_m [M, 2] moving at
        uav_velocity_mps [M, 2] relative to every party (UAV m's own column is zero)."""
        return (
            np.asarray(uav_xy_m)[:, None] - self.xy_m[None],
            np.asarray(uav_velocity_mps)[:, None] - self.velocity_mps[None],
        )


def closest_approach(
    relative_xy_m: FloatArray, relative_velocity_mps: FloatArray, horizon_s: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(time [...] s, distance [...] m) of the closest approach of relative motions coasting from
    relative_xy_m [..., 2] at relative_velocity_mps [..., 2], within [0, horizon_s [...]]."""
    speed2 = np.einsum("...i,...i->...", relative_velocity_mps, relative_velocity_mps)
    along = np.einsum("...i,...i->...", relative_xy_m, relative_velocity_mps)
    t = np.clip(-along / np.maximum(speed2, 1e-12), 0.0, horizon_s)
    distance = np.linalg.norm(relative_xy_m + relative_velocity_mps * t[..., None], axis=-1)
    return np.asarray(t), np.asarray(distance)


def coasting_threats(
    parties: Parties, a_max_mps2: float, dt_s: float
) -> tuple[BoolArray, FloatArray]:
    """(threat [M, P], time of closest approach [M, P] s): party p threatens UAV m when their
    coasting motions come within p's clearance inside dt + |relative velocity| / a_max."""
    M = int(parties.braking.sum())
    rel_xy, rel_v = parties.relative_to(parties.xy_m[:M], parties.velocity_mps[:M])
    look_ahead_s = dt_s + np.linalg.norm(rel_v, axis=-1) / a_max_mps2
    t, distance = closest_approach(rel_xy, rel_v, look_ahead_s)
    threat = distance < parties.clearance_m[None]
    threat[np.arange(M), np.arange(M)] = False
    return np.asarray(threat), t


def unviable_pairs(
    parties: Parties, end_xy_m: FloatArray, end_velocity_mps: FloatArray, a_max_mps2: float
) -> BoolArray:
    """[M, P] True where UAV m, ending its slot at end_xy_m [M, 2] with end_velocity_mps [M, 2],
    cannot brake before the clearance of party p: another UAV at its own end state (both brake,
    2 a_max) or a keep-out point (a_max alone). The target's column is False (module docstring).
    Symmetric on the UAV block."""
    M = len(end_xy_m)
    others_xy = np.vstack([end_xy_m, parties.xy_m[M:]])
    others_v = np.vstack([end_velocity_mps, parties.velocity_mps[M:]])
    rel_xy = np.asarray(end_xy_m)[:, None] - others_xy[None]
    rel_v = np.asarray(end_velocity_mps)[:, None] - others_v[None]
    gap = np.linalg.norm(rel_xy, axis=-1)
    closing = np.maximum(-np.einsum("mpi,mpi->mp", rel_xy, rel_v) / np.maximum(gap, 1e-12), 0.0)
    authority = np.where(parties.braking, 2 * a_max_mps2, a_max_mps2)[None]
    short = closing**2 / (2 * authority) > gap - parties.clearance_m[None] + VIABILITY_TOL_M
    short[np.arange(M), np.arange(M)] = False
    short[:, M] = False
    return np.asarray(short)


ESCAPE_STEPS_PER_SLOT = 8
"""Time steps per slot of the simulated dodges of `target_escape`."""


def target_escape(
    uav_xy_m: FloatArray,
    uav_velocity_mps: FloatArray,
    target_xy_m: FloatArray,
    target_velocity_mps: FloatArray,
    clearance_m: float,
    a_max_mps2: float,
    a_target_mps2: float,
    v_max_mps: float,
    dt_s: float,
    known_s: float = 0.0,
) -> tuple[BoolArray, FloatArray]:
    """(viable [M], direction [M, 2]): can each UAV at uav_xy_m [M, 2], moving at
    uav_velocity_mps [M, 2], keep clearance_m from the target at target_xy_m [2] moving at
    target_velocity_mps [2] and accelerating at up to a_target_mps2 (a_T) off that motion, by a
    dodge it could start now?

    The UAV coasts, or accelerates at a_max along one of three fixed directions (away from the
    target now, across their relative velocity on the side it already misses by, the bisector of
    the two), a slot at a time on the constant-acceleration legs `evasive_legs` flies
    (`evasive_velocity`: speed within V_max), each sampled at ESCAPE_STEPS_PER_SLOT instants.
    The target's state was known known_s ago (the slot's start, for a check of its end: its
    position then was within a_T dt^2 / 2, its velocity within a_T dt, of the constant-velocity
    motion given), so at time t its worst motion is anywhere within a_T (t + known_s)^2 / 2 of
    that motion, and a UAV motion keeps the target away if its distance to it is at least
    clearance_m + a_T (t + known_s)^2 / 2 at every sample. Viable: one of the four motions does,
    within the look-ahead dt + (|relative velocity| + sqrt(2 c A)) / A, A = a_max - a_T, that
    the UAV needs to cancel their closing speed and step the clearance aside (a farther
    encounter is next slot's to dodge). direction: the dodge (of the three) whose worst margin
    is largest."""
    xy = np.asarray(uav_xy_m, dtype=float)
    v0 = np.asarray(uav_velocity_mps, dtype=float)
    p_t = np.asarray(target_xy_m, dtype=float).reshape(2)
    v_t = np.asarray(target_velocity_mps, dtype=float).reshape(2)
    M = len(xy)
    rel, rel_v = xy - p_t, v0 - v_t
    speed = np.linalg.norm(rel_v, axis=1)
    net = max(a_max_mps2 - a_target_mps2, 0.1 * a_max_mps2)
    look_ahead_s = dt_s + (speed + np.sqrt(2 * clearance_m * net)) / net
    away = rel / np.maximum(np.linalg.norm(rel, axis=1), 1e-12)[:, None]
    across = np.stack([-rel_v[:, 1], rel_v[:, 0]], axis=1) / np.maximum(speed, 1e-12)[:, None]
    across *= np.where(np.einsum("mi,mi->m", across, rel) < 0, -1.0, 1.0)[:, None]
    across = np.where(speed[:, None] > 1e-9, across, away)
    bisector = away + across
    bisector /= np.maximum(np.linalg.norm(bisector, axis=1), 1e-12)[:, None]
    coast = np.zeros_like(away)
    directions = np.stack([coast, away, across, bisector], axis=1)  # [M, 4, 2]
    slots = int(np.ceil(float(np.max(look_ahead_s, initial=0.0)) / dt_s))
    tau = np.arange(1, ESCAPE_STEPS_PER_SLOT + 1) / ESCAPE_STEPS_PER_SLOT  # [S] in (0, 1]
    p, v = np.repeat(xy[:, None], 4, axis=1), np.repeat(v0[:, None], 4, axis=1)
    margin = np.repeat(np.linalg.norm(rel, axis=1)[:, None], 4, axis=1) - clearance_m
    for k in range(slots):
        v1 = v.copy()  # the coasting motion keeps its velocity; the dodges accelerate
        v1[:, 1:] = evasive_velocity(v[:, 1:], directions[:, 1:], a_max_mps2, v_max_mps, dt_s)
        t_s = (k + tau) * dt_s  # [S]
        pts = (
            p[:, :, None]
            + v[:, :, None] * (tau * dt_s)[:, None]
            + 0.5 * (v1 - v)[:, :, None] * (tau**2 * dt_s)[:, None]
        )  # [M, 4, S, 2]
        gap = np.linalg.norm(pts - (p_t + t_s[:, None] * v_t), axis=-1)
        need = clearance_m + 0.5 * a_target_mps2 * (t_s + known_s) ** 2
        slack = np.where(t_s <= look_ahead_s[:, None, None], gap - need, np.inf)
        margin = np.minimum(margin, slack.min(axis=-1))
        p, v = pts[:, :, -1], v1
    viable = margin.max(axis=1) >= -VIABILITY_TOL_M
    best = 1 + np.argmax(margin[:, 1:], axis=1)
    return np.asarray(viable), np.asarray(directions[np.arange(M), best])


def evasive_velocity(
    v0_mps: FloatArray, direction: FloatArray, a_max_mps2: float, v_max_mps: float, dt_s: float
) -> FloatArray:
    """The end velocity v1 [..., 2] (m/s) of the constant-acceleration leg that accelerates
    furthest along the unit vector `direction` [..., 2] from v0_mps [..., 2]: v1 maximises
    (v1 - v0) . direction over the intersection of |v1 - v0| <= a_max dt and |v1| <= V_max. That
    set is convex, so the optimum is v0 + a_max dt direction, V_max direction, or a point where
    the two circles cross, whichever is feasible and best; a vehicle faster than
    V_max + a_max dt brakes at a_max."""
    v0 = np.asarray(v0_mps, dtype=float)
    u = np.broadcast_to(np.asarray(direction, dtype=float), v0.shape)
    reach = a_max_mps2 * dt_s
    v_cap = v_max_mps * (1 - 1e-9)
    speed = np.linalg.norm(v0, axis=-1, keepdims=True)
    e = v0 / np.maximum(speed, 1e-12)
    n = np.stack([-e[..., 1], e[..., 0]], axis=-1)
    along = (v_cap**2 - reach**2 + speed**2) / (2 * np.maximum(speed, 1e-12))
    across = np.sqrt(np.maximum(v_cap**2 - along**2, 0.0))
    crossing = (speed > 1e-12) & (abs(reach - v_cap) <= speed) & (speed <= reach + v_cap)
    candidates = np.stack(
        [v0 + reach * u, v_cap * u, along * e + across * n, along * e - across * n], axis=-2
    )  # [..., 4, 2]
    feasible = (
        (np.linalg.norm(candidates - v0[..., None, :], axis=-1) <= reach * (1 + 1e-9))
        & (np.linalg.norm(candidates, axis=-1) <= v_max_mps)
        & np.concatenate([np.ones((*crossing.shape[:-1], 2), bool), crossing.repeat(2, -1)], -1)
    )
    gain = np.where(
        feasible, np.einsum("...ki,...i->...k", candidates - v0[..., None, :], u), -np.inf
    )
    best = np.take_along_axis(candidates, np.argmax(gain, axis=-1)[..., None, None], axis=-2)[
        ..., 0, :
    ]
    brake = v0 - reach * e
    return np.asarray(np.where(feasible.any(axis=-1, keepdims=True), best, brake))


def evasive_legs(
    parties: Parties,
    threat: BoolArray,
    base_xy_m: FloatArray,
    base_velocity_mps: FloatArray,
    a_max_mps2: float,
    v_max_mps: float,
    dt_s: float,
    target_direction: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """(end points [M, 2] m, end velocities [M, 2] m/s, evading [M]): every UAV with a threat
    (threat [M, P]) flies its evasive leg (module docstring), the others keep base_xy_m [M, 2]
    and base_velocity_mps [M, 2]. target_direction [M, 2]: the unit vector each UAV dodges the
    target along (`target_escape`), instead of straight away from it."""
    M = len(base_xy_m)
    p0, v0 = parties.xy_m[:M], parties.velocity_mps[:M]
    rel_xy, rel_v = parties.relative_to(p0, v0)
    t, _ = closest_approach(rel_xy, rel_v, np.full(threat.shape, np.inf))
    now = np.linalg.norm(rel_xy, axis=-1)
    away = rel_xy / np.maximum(now, 1e-12)[..., None]
    if target_direction is not None:
        away[:, M] = target_direction
    push = np.einsum("mp,mpi->mi", threat / np.maximum(t, dt_s), away)
    norm = np.linalg.norm(push, axis=-1)
    evading = threat.any(axis=1) & (norm > 1e-12)
    xy = np.array(base_xy_m, dtype=float)
    velocity = np.array(base_velocity_mps, dtype=float)
    for m in np.flatnonzero(evading):
        u = push[m] / norm[m]
        aways = away[m, threat[m]]
        if np.min(aways @ u) < 0:
            u = away_from_all(aways, u)
        velocity[m] = evasive_velocity(v0[m], u, a_max_mps2, v_max_mps, dt_s)
        xy[m] = p0[m] + 0.5 * (v0[m] + velocity[m]) * dt_s
    return xy, velocity, np.asarray(evading)


def away_from_all(aways: FloatArray, push: FloatArray) -> FloatArray:
    """The unit vector u that maximises min_p u . aways[p] (aways [T, 2], unit vectors away
    from T threats), the one nearest the push (unit [2]) among near-equals: for a UAV between
    two threats, the weighted push away from the nearer one drives it into the other (the
    M = 3 soak's arrival: away from a UAV 33 m behind, into the target 42 m ahead), where the
    sideways dodge moves away from both. Exact: on the circle a min of the u . aways[p] is
    largest where one of them is (an away) or where two are equal (u = +-(a_p + a_q) / |.|, or
    a perpendicular to a_p where a_q = -a_p), and these are the candidates."""
    perp = np.stack([-aways[:, 1], aways[:, 0]], axis=1)
    i, j = np.triu_indices(len(aways), 1)
    sums = aways[i] + aways[j]
    candidates = np.concatenate([aways, perp, -perp, sums, -sums, push[None]])
    norm = np.linalg.norm(candidates, axis=1)
    candidates = candidates[norm > 1e-9] / norm[norm > 1e-9, None]  # opposite aways sum to 0
    worst = np.min(candidates @ aways.T, axis=1)
    near = worst >= worst.max() - 1e-9
    return np.asarray(candidates[near][np.argmax(candidates[near] @ push)])
