"""Single-scan track initiation from several moving sensors (docs/model.md, "The multi-target
tracker"): a target is found from one slot's reports when three or more UAVs measured it.

One UAV's (range, Doppler) pair does not locate a target; two UAVs' do, up to the mirror image
about the line through them: the two range circles meet in at most two points p, and the two
radial velocities v_m = u_m . v (u_m the unit vector from UAV m to p) give the velocity v. So
every pair of UAVs (a, b) and every pair of their measurements (i, j) proposes up to two states
x = [p, v], with covariance Sigma = H^-1 R H^-T (H [4, 4] the Jacobian of the four
measurements, R their variances). A proposal is supported by another UAV c when one of c's
measurements falls inside the gate of the predicted measurement h_c(x) with innovation
covariance H_c Sigma H_c^T + R_c (the nearest one). Each set of measurements counts once; the
sets are taken greedily, most UAVs first, each measurement used once, and kept when a fit of
all their measurements passes: a chi-square test of the residual with 2 n - 4 degrees of freedom
(n its UAVs), a position known to `max_position_std_m`, a speed below `max_speed_mps`, a position
inside the area. Initiation sees only the measurements no track explains (letting explained
ones in too was measured to start ghosts beside every tracked target: docs/model.md).

The fit (Levenberg-Marquardt, every start at once) starts from the proposal and from every
pair of its UAVs' crossings, since coarse ranges leave local minima: when no minimum passes,
the measurement that fits worst is dropped (a false alarm a broad gate let in) and the rest
fitted again, down to `min_uavs`. An ambiguous fit waits: when two minima pass but lie outside
each other's gates, or another proposal sharing `min_uavs` of the winner's measurements passes
elsewhere with as many UAVs' measurements (the mirror image about a line of UAVs, or a ghost),
no track starts this slot and their measurements are spent. A rival that passes only with fewer
(a false alarm kept, true measurements dropped) does not hold the winner back.

Pure: numpy and scipy. Shapes: M UAVs, k_m measurements of UAV m, S starts, L proposals.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from isac_mission.config.targets import DetectionSpec
from isac_mission.model.detections import detection_probability
from isac_mission.model.radar import SensingParams
from isac_mission.tracking.association import gate_threshold
from isac_mission.types import FloatArray, Gaussian

_MIN_LOS_SINE = 0.05
"""Pairs whose lines of sight to a proposal are nearer parallel than this (about 3 degrees) see
one velocity component only: no proposal."""


@dataclass(frozen=True)
class InitiationSettings:
    """gate_prob: the probability of the supporters' gate and of the refined residual's test;
    max_position_std_m: the largest sqrt(tr(P_pos) / 2) a new track may start with (m);
    max_speed_mps: the fastest target there is (a proposal faster than this is clutter);
    min_uavs: how many UAVs must have measured a target to start a track on it, at least;
    min_detected_share: ... and at least this share of the UAVs expected to detect it there
    (the sum of their P_d by `detection`, None: P_d = 1); area_m: the operating area's size
    (x, y from 0, m) where tracks start (None: anywhere); max_starts: the most precise UAVs
    whose pairs start the fit; max_pairs: about how many pairs of UAVs propose; max_rivals: how
    many of the next proposals sharing a winner's measurements are fitted to test it for
    ambiguity (module docstring)."""

    gate_prob: float = 0.999
    max_position_std_m: float = 150.0
    max_speed_mps: float = 60.0
    min_uavs: int = 3
    min_detected_share: float = 0.5
    detection: DetectionSpec | None = None
    area_m: tuple[float, float] | None = None
    max_starts: int = 4
    max_pairs: int = 60
    max_rivals: int = 4


AMBIGUOUS_LIKELIHOOD_RATIO = 20.0
"""A second passing fit elsewhere makes a fit ambiguous unless the first is more than this many
times as likely (the mirror image about a line of UAVs is about as likely; a far minimum that
passes on the large variances of its own ranges is not)."""

REFIT_ITERATIONS = 15
"""Levenberg-Marquardt steps of the refit at the predicted ranges' variances: it starts at a
minimum of the first fit, a few metres from its own."""

Members = tuple[tuple[int, int], ...]
"""Measurements as (UAV, index into its measurements) pairs."""


@dataclass(frozen=True)
class _Proposal:
    """One proposed state x [4] with its measurements, the sum of its supporters' squared
    distances, and how many UAVs a track there needs (`_required`)."""

    x: FloatArray
    members: Members
    distance2: float
    required: int


def _pair_states(
    qa: FloatArray, za: FloatArray, qb: FloatArray, zb: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The states [L, 4] that UAVs at qa, qb [2] with measurements za [ka, 2], zb [kb, 2]
    propose, and their measurement indices [L, 2] (into za, zb); up to two per pair."""
    grid_a, grid_b = np.meshgrid(np.arange(len(za)), np.arange(len(zb)), indexing="ij")
    ia, ib = grid_a.ravel(), grid_b.ravel()
    ra, rb = za[ia, 0], zb[ib, 0]
    base = qb - qa
    D = float(np.linalg.norm(base))
    e = base / D
    e_perp = np.array([-e[1], e[0]])
    along = (ra**2 - rb**2 + D**2) / (2 * D)
    # Circles that miss each other by the noise meet at their nearest points (h = 0): the
    # supporters' gate then judges the proposal.
    h = np.sqrt(np.maximum(ra**2 - along**2, 0.0))
    points = np.concatenate(
        [qa + along[:, None] * e + s * h[:, None] * e_perp for s in (1.0, -1.0)]
    )
    index = np.concatenate([np.stack([ia, ib], axis=1)] * 2)
    ua = points - qa
    ub = points - qb
    ua /= np.linalg.norm(ua, axis=1, keepdims=True)
    ub /= np.linalg.norm(ub, axis=1, keepdims=True)
    A = np.stack([ua, ub], axis=1)  # [L, 2, 2]: rows u_a, u_b
    sine = np.abs(ua[:, 0] * ub[:, 1] - ua[:, 1] * ub[:, 0])
    ok = sine > _MIN_LOS_SINE
    doppler = np.stack([za[index[:, 0], 1], zb[index[:, 1], 1]], axis=1)
    v = np.zeros_like(points)
    if np.any(ok):
        v[ok] = np.linalg.solve(A[ok], doppler[ok][..., None])[..., 0]
    return np.concatenate([points, v], axis=1)[ok], index[ok]


def _predicted(x: FloatArray, uav_xy: FloatArray) -> FloatArray:
    """[L, 2]: (range, Doppler) of each state x [L, 4] seen from uav_xy [2]."""
    r = x[:, :2] - uav_xy
    d = np.linalg.norm(r, axis=1)
    return np.stack([d, np.einsum("li,li->l", r, x[:, 2:]) / d], axis=1)


def _variances(sensing: SensingParams, range_m: FloatArray, eta: float) -> FloatArray:
    """[L, 2]: sigma_d^2, sigma_v^2 (m^2, m^2/s^2) at the ranges [L] for a UAV of share eta."""
    r = np.asarray(range_m, dtype=float)
    return sensing.variances(r, np.full(r.shape, eta)).reshape(2, -1).T


def _pairs(seen: list[int], max_pairs: int) -> list[tuple[int, int]]:
    """The pairs of UAVs that propose: every pair of `seen` while there are at most max_pairs,
    else each UAV with partners spread evenly around the list (about max_pairs pairs: a target
    that many UAVs see is proposed by one of them all the same)."""
    every = list(itertools.combinations(seen, 2))
    if len(every) <= max_pairs:
        return every
    n = len(seen)
    per_uav = max(1, max_pairs // n)
    step = max(1, n // (per_uav + 1))
    pairs = {
        tuple(sorted((seen[i], seen[(i + 1 + j * step) % n])))
        for i in range(n)
        for j in range(per_uav)
    }
    return sorted((a, b) for a, b in pairs if a != b)


def _proposals(
    measurements: Sequence[FloatArray],
    uav_xy_m: FloatArray,
    eta: FloatArray,
    sensing: SensingParams,
    gate: float,
    settings: InitiationSettings,
) -> list[_Proposal]:
    """The pairs' proposals (`_pairs`) with the supporters each gathers (at most one
    measurement per UAV: the nearest in the gate), those with fewer UAVs than `_required`
    left out; proposals too fast or outside the area are dropped before their support is
    sought. Every pair's states are gated against each other UAV at once."""
    seen = [m for m in range(len(measurements)) if len(measurements[m]) and eta[m] > 0]
    xs, firsts, seconds, sigmas = [], [], [], []
    for a, b in _pairs(seen, settings.max_pairs):
        x, index = _pair_states(uav_xy_m[a], measurements[a], uav_xy_m[b], measurements[b])
        plausible = np.linalg.norm(x[:, 2:], axis=1) <= settings.max_speed_mps
        if settings.area_m is not None:
            margin = settings.max_position_std_m
            plausible &= np.all(
                (x[:, :2] >= -margin) & (x[:, :2] <= np.asarray(settings.area_m) + margin), axis=1
            )
        x, index = x[plausible], index[plausible]
        if not len(x):
            continue
        H = _measure_many(x, uav_xy_m[[a, b]])[1]  # rows: range a, range b, Doppler a, Doppler b
        r_a = _variances(sensing, measurements[a][index[:, 0], 0], float(eta[a]))
        r_b = _variances(sensing, measurements[b][index[:, 1], 0], float(eta[b]))
        R = np.stack([r_a[:, 0], r_b[:, 0], r_a[:, 1], r_b[:, 1]], axis=1)
        ok = np.abs(np.linalg.det(H)) > 1e-12
        H_inv = np.linalg.inv(H[ok])
        xs.append(x[ok])
        firsts.append(np.stack([np.full(int(ok.sum()), a), index[ok, 0]], axis=1))
        seconds.append(np.stack([np.full(int(ok.sum()), b), index[ok, 1]], axis=1))
        sigmas.append(np.einsum("lij,lj,lkj->lik", H_inv, R[ok], H_inv))
    if not xs:
        return []
    x = np.concatenate(xs)
    first, second, Sigma = np.concatenate(firsts), np.concatenate(seconds), np.concatenate(sigmas)
    L = len(x)
    chosen = np.full((L, len(measurements)), -1, dtype=np.int64)
    total = np.zeros(L)
    for c in seen:
        rows = np.flatnonzero((first[:, 0] != c) & (second[:, 0] != c))
        z_hat = _predicted(x[rows], uav_xy_m[c])
        H_c = _measure_many(x[rows], uav_xy_m[c : c + 1])[1]
        S = np.einsum("lij,ljk,lmk->lim", H_c, Sigma[rows], H_c)
        S[:, [0, 1], [0, 1]] += _variances(sensing, z_hat[:, 0], float(eta[c]))
        nu = measurements[c][None, :, :] - z_hat[:, None, :]  # [L', k_c, 2]
        d2 = np.einsum("lki,lij,lkj->lk", nu, np.linalg.inv(S), nu)
        best = np.argmin(d2, axis=1)
        best_d2 = d2[np.arange(len(rows)), best]
        inside = best_d2 <= gate
        chosen[rows[inside], c] = best[inside]
        total[rows[inside]] += best_d2[inside]
    n_uavs = 2 + np.sum(chosen >= 0, axis=1)
    sensed = uav_xy_m[np.asarray(eta) > 0]
    out: list[_Proposal] = []
    for row in np.flatnonzero(n_uavs >= settings.min_uavs):
        need = _required(x[row], sensed, sensing, settings)
        if n_uavs[row] < need:
            continue
        support = tuple((int(c), int(chosen[row, c])) for c in np.flatnonzero(chosen[row] >= 0))
        pair = (
            (int(first[row, 0]), int(first[row, 1])),
            (int(second[row, 0]), int(second[row, 1])),
        )
        out.append(_Proposal(x[row], pair + support, float(total[row]), need))
    return out


@dataclass(frozen=True)
class _Fit:
    """A fit of some measurements: belief (x [4], P = (H^T W H)^-1), chi_square of the residual,
    member_chi_square [n] each UAV's part of it, and deviance = chi_square + sum of the log
    variances at the fit (-2 log-likelihood up to a constant: the noise of eq. 8 grows as d^4,
    so a far minimum passes the chi-square test on its own large variances, and only the
    likelihood tells it from the near one)."""

    belief: Gaussian
    chi_square: float
    member_chi_square: FloatArray
    deviance: float = 0.0


def _measure_many(x: FloatArray, uavs_xy: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(h [S, 2n], H [S, 2n, 4]): the ranges then Dopplers of states x [S, 4] seen from the UAVs
    at uavs_xy [n, 2] (eq. 6), and their Jacobians (eq. 10's rows)."""
    r = x[:, None, :2] - uavs_xy[None]  # [S, n, 2]
    d = np.linalg.norm(r, axis=2)
    u = r / d[..., None]
    v_r = np.einsum("sni,si->sn", u, x[:, 2:])
    S, n = d.shape
    H = np.zeros((S, 2 * n, 4))
    H[:, :n, :2] = u
    H[:, n:, :2] = (x[:, None, 2:] - v_r[..., None] * u) / d[..., None]
    H[:, n:, 2:] = u
    return np.concatenate([d, v_r], axis=1), H


def _fit_many(
    starts: FloatArray, z_flat: FloatArray, w: FloatArray, uavs_xy: FloatArray, iterations: int = 40
) -> list[_Fit]:
    """Levenberg-Marquardt from each start [S, 4] at once on measurements z_flat [2n] (ranges,
    then Dopplers) with weights w [2n], or [S, 2n] one set per start (inverse variances), from
    UAVs at uavs_xy [n, 2]; a fit whose H^T W H is singular is left out."""
    x = np.asarray(starts, dtype=float).copy()
    W = np.broadcast_to(np.asarray(w, dtype=float), (len(x), len(z_flat)))

    def costs(x: FloatArray, w: FloatArray) -> FloatArray:
        res = z_flat[None] - _measure_many(x, uavs_xy)[0]
        return np.asarray(np.einsum("sk,sk,sk->s", res, w, res))

    f = costs(x, W)
    damping = np.full(len(x), 1e-3)
    active = np.isfinite(f)
    for _ in range(iterations):
        if not active.any():
            break
        w_a = W[active]
        h, H = _measure_many(x[active], uavs_xy)
        info = np.einsum("ski,sk,skj->sij", H, w_a, H)
        g = np.einsum("ski,sk,sk->si", H, w_a, z_flat[None] - h)
        lifted = info + damping[active, None, None] * (np.eye(4)[None] * info)
        ok = np.linalg.det(lifted) > 0
        step = np.zeros_like(g)
        step[ok] = np.linalg.solve(lifted[ok], g[ok][..., None])[..., 0]
        trial = x[active] + step
        f_trial = costs(trial, w_a)
        better = ok & (f_trial < f[active])
        idx = np.flatnonzero(active)
        done = better & (f[active] - f_trial <= 1e-10 * np.maximum(f_trial, 1.0))
        x[idx[better]], f[idx[better]] = trial[better], f_trial[better]
        damping[idx[better]] = np.maximum(damping[idx[better]] / 10, 1e-9)
        damping[idx[~better]] *= 10
        active[idx[done | (damping[idx] > 1e9) | ~ok]] = False
    h, H = _measure_many(x, uavs_xy)
    info = np.einsum("ski,sk,skj->sij", H, W, H)
    r2 = W * (z_flat[None] - h) ** 2
    n = len(uavs_xy)
    out = []
    for s in range(len(x)):
        if not np.all(np.isfinite(info[s])) or np.linalg.cond(info[s]) > 1e14:
            continue
        P = np.linalg.inv(info[s])
        member = r2[s, :n] + r2[s, n:]
        chi_square = float(r2[s].sum())
        deviance = chi_square - float(np.sum(np.log(W[s])))
        out.append(_Fit(Gaussian(x=x[s], P=0.5 * (P + P.T)), chi_square, member, deviance))
    return out


def _fits(
    members: Members,
    x0: FloatArray,
    measurements: Sequence[FloatArray],
    uav_xy_m: FloatArray,
    eta: FloatArray,
    sensing: SensingParams,
    settings: InitiationSettings,
) -> list[_Fit]:
    """The fits of the members' measurements ((UAV, index) pairs) from x0 [4] and from the
    starts that the pairs of its `settings.max_starts` most precise UAVs (finest range) propose (both
    circle crossings of each pair): the local minima found, each once, the most likely
    (lowest deviance) first."""
    uavs = np.array([m for m, _ in members])
    z = np.array([measurements[m][j] for m, j in members])
    z_flat = np.concatenate([z[:, 0], z[:, 1]])
    r = np.array(
        [_variances(sensing, z[i : i + 1, 0], float(eta[m]))[0] for i, m in enumerate(uavs)]
    )
    w = 1.0 / np.concatenate([r[:, 0], r[:, 1]])
    starts = [x0]
    precise = np.argsort(r[:, 0], kind="stable")[: settings.max_starts]
    for i, k in itertools.combinations(sorted(precise.tolist()), 2):
        x, _ = _pair_states(uav_xy_m[uavs[i]], z[i : i + 1], uav_xy_m[uavs[k]], z[k : k + 1])
        starts += [s for s in x if np.linalg.norm(s[2:]) <= settings.max_speed_mps]
    found = _distinct(_fit_many(np.array(starts), z_flat, w, uav_xy_m[uavs]))
    if found:
        # Eq. 8's variances belong to the true range, not the measured one: a coarse range
        # measured 30 % short had its variance taken 4x too small, and the residual of the
        # true measurements of a far target failed its chi-square test. Fitted again from each
        # minimum with the variances at its own predicted ranges, and tested with those.
        at = np.array([f.belief.x for f in found])
        predicted = _measure_many(at, uav_xy_m[uavs])[0][:, : len(uavs)]  # [S, n] ranges
        r_at = sensing.variances(predicted.ravel(), np.tile(eta[uavs], len(at)))
        k = predicted.size
        w_at = 1.0 / np.concatenate(
            [r_at[:k].reshape(predicted.shape), r_at[k:].reshape(predicted.shape)], axis=1
        )
        found = _fit_many(at, z_flat, w_at, uav_xy_m[uavs], iterations=REFIT_ITERATIONS)
    return _distinct(sorted(found, key=lambda f: f.deviance))


def _distinct(fits: Sequence[_Fit]) -> list[_Fit]:
    """The fits in their order, each place once (a fit within 1 m of an earlier one dropped:
    several starts reach the same minimum)."""
    minima: list[_Fit] = []
    for fit in fits:
        if not any(np.linalg.norm(fit.belief.x[:2] - m.belief.x[:2]) < 1.0 for m in minima):
            minima.append(fit)
    return minima


def initiate(
    measurements: Sequence[FloatArray],
    uav_xy_m: FloatArray,
    eta: FloatArray,
    sensing: SensingParams,
    settings: InitiationSettings,
) -> list[Gaussian]:
    """New tracks' beliefs (x [4] in m and m/s, P [4, 4]) from one slot's measurements that no
    track explains [M] (arrays [k_m, 2] of range m and Doppler m/s) taken at uav_xy_m [M, 2]
    with shares eta [M] (a UAV with eta <= 0 measured nothing). `sensing` gives eq. 8's
    variances (at a nominal RCS: the tracker does not know an unknown target's)."""
    sensing_uavs = sum(1 for m, z in enumerate(measurements) if len(z) and eta[m] > 0)
    if sensing_uavs < settings.min_uavs:
        return []
    gate = _gate(settings)
    proposals = _proposals(measurements, uav_xy_m, eta, sensing, gate, settings)
    proposals.sort(key=lambda p: (-len(p.members), p.distance2))
    # One proposal per set of measurements (each pair of a set proposes it again).
    distinct: dict[frozenset[tuple[int, int]], _Proposal] = {}
    for p in proposals:
        distinct.setdefault(frozenset(p.members), p)
    proposals = list(distinct.values())
    verdicts: dict[frozenset[tuple[int, int]], tuple[_Fit, Members] | None] = {}
    used: set[tuple[int, int]] = set()
    out: list[Gaussian] = []

    def accepted(p: _Proposal) -> tuple[_Fit, Members] | None:
        """The proposal's one passing fit and the measurements it used; None when none passes
        or the fit is ambiguous (once per proposal)."""
        key = frozenset(p.members)
        if key not in verdicts:
            verdicts[key] = verdict(p)
        return verdicts[key]

    def verdict(p: _Proposal) -> tuple[_Fit, Members] | None:
        members = p.members
        while len(members) >= p.required:
            found = _fits(members, p.x, measurements, uav_xy_m, eta, sensing, settings)
            good = [fit for fit in found if _passes(fit, settings)]
            if good:
                best = _unique(good, gate)
                return None if best is None else (best, members)
            if not found:
                return None
            worst = int(np.argmax(found[0].member_chi_square))
            members = members[:worst] + members[worst + 1 :]
        return None

    for i, p in enumerate(proposals):
        if len(p.members) < p.required or used.intersection(p.members):
            continue
        winner = accepted(p)
        if winner is None:
            continue
        fit, members = winner
        used.update(members)
        rivals = [
            q for q in proposals[i + 1 :] if len(set(q.members) & set(members)) >= settings.min_uavs
        ][: settings.max_rivals]
        # A rival is another explanation of as many UAVs' measurements, about as likely: one
        # that passes only after dropping some (a false alarm kept in their place) explains
        # less, and coarse ranges give such partial fits somewhere else almost always.
        if not any(
            (rival := accepted(q)) is not None
            and len(rival[1]) >= len(members)
            and _rivals(fit, rival[0], gate)
            for q in rivals
        ):
            out.append(fit.belief)
    return out


def refit(
    z_by_uav: dict[int, FloatArray],
    x0: FloatArray,
    uav_xy_m: FloatArray,
    eta: FloatArray,
    sensing: SensingParams,
    settings: InitiationSettings,
) -> Gaussian | None:
    """A state from one slot's measurements known to be one target's, z_by_uav {UAV: [2]}
    (range m, Doppler m/s), fitted from x0 [4] and every pair's crossings: the one fit that
    passes initiation's tests (None: none, or an ambiguous one)."""
    measurements = [np.zeros((0, 2))] * len(uav_xy_m)
    for m, z in z_by_uav.items():
        measurements[m] = np.asarray(z, dtype=float).reshape(1, 2)
    members = tuple((m, 0) for m in sorted(z_by_uav))
    found = _fits(members, x0, measurements, uav_xy_m, eta, sensing, settings)
    best = _unique([fit for fit in found if _passes(fit, settings)], _gate(settings))
    return None if best is None else best.belief


def _required(
    x: FloatArray, uav_xy_m: FloatArray, sensing: SensingParams, settings: InitiationSettings
) -> int:
    """How many UAVs must have measured a target at state x [4] to start a track there:
    min_uavs, or min_detected_share of the detections expected from the sensing UAVs at
    uav_xy_m [M', 2] (P_d at each one's range), whichever is more."""
    if settings.detection is None:
        expected = float(len(uav_xy_m))
    else:
        range_m = np.linalg.norm(uav_xy_m - x[:2], axis=1)
        gains = np.full(len(range_m), sensing.radar_gain)
        pd = detection_probability(range_m, gains, settings.detection, sensing.B, sensing.Ts)
        expected = float(np.sum(pd))
    return max(settings.min_uavs, math.ceil(settings.min_detected_share * expected - 1e-9))


def _gate(settings: InitiationSettings) -> float:
    return gate_threshold(settings.gate_prob, 2)


def _passes(fit: _Fit, settings: InitiationSettings) -> bool:
    """Initiation's tests of a fit: its residual, position std, speed and place."""
    belief, n = fit.belief, len(fit.member_chi_square)
    position_std_m = float(np.sqrt(np.trace(belief.P[:2, :2]) / 2))
    x, y = belief.x[:2]
    inside = settings.area_m is None or (
        0 <= x <= settings.area_m[0] and 0 <= y <= settings.area_m[1]
    )
    return bool(
        fit.chi_square <= gate_threshold(settings.gate_prob, 2 * n - 4)
        and position_std_m <= settings.max_position_std_m
        and np.linalg.norm(belief.x[2:]) <= settings.max_speed_mps
        and inside
    )


def _unique(good: Sequence[_Fit], gate: float) -> _Fit | None:
    """The best of the passing fits good (the most likely first), None when a rival of it is
    among the others (ambiguous: `_rivals`) or there is none."""
    if not good or any(_rivals(good[0], other, gate) for other in good[1:]):
        return None
    return good[0]


def _rivals(best: _Fit, other: _Fit, gate: float) -> bool:
    """Whether `other` is another place the target may be as well as at `best`: outside its
    gate and at most AMBIGUOUS_LIKELIHOOD_RATIO times less likely."""
    margin = 2.0 * math.log(AMBIGUOUS_LIKELIHOOD_RATIO)
    return other.deviance - best.deviance <= margin and outside_gate(
        best.belief, other.belief, gate
    )


def outside_gate(a: Gaussian, b: Gaussian, gate: float) -> bool:
    """Whether b's position lies outside a's and b's joint position gate (chi-square value
    gate: the tracker's test of a second track on one target, a refutation, an ambiguity)."""
    e = a.x[:2] - b.x[:2]
    return float(e @ np.linalg.solve(a.P[:2, :2] + b.P[:2, :2], e)) > gate
