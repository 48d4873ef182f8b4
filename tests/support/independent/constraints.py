"""The paper's constraints (14a)-(14j), re-derived and checked slot by slot on a trace.

Units: SI throughout; positions [M, 2] in the scenario plane (see the package doc).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from tests.support.independent.common import Array, as_trace, config_value

CONSTRAINTS = ("14a", "14b", "14c", "14d", "14e", "14f/g", "14h", "14i", "14j")
"""The labels check_constraints uses (14e is the N_a capacity; 14f and 14g are checked together:
each UAV must name exactly one valid BS)."""


@dataclass(frozen=True)
class Violation:
    """One broken constraint at one slot.

    constraint: "14a" .. "14j" (see CONSTRAINTS); uavs: 0-based UAV indices involved (for 14e
    the UAVs sharing the over-full BS); value and limit in the constraint's own unit (bit/s for
    14a, m for 14b/14h/14i/14j, a share for 14c/14d, a count for 14e, the BS index for 14f/g);
    status: the slot's logged status, so the caller can decide what an infeasible slot may break.
    """

    slot: int
    constraint: str
    uavs: tuple[int, ...]
    value: float
    limit: float
    status: str
    detail: str

    def __str__(self) -> str:
        who = ",".join(str(m) for m in self.uavs)
        return (
            f"slot {self.slot} ({self.status}): {self.constraint} UAV {who}: {self.detail}: "
            f"{self.value:.9g} vs limit {self.limit:.9g}"
        )


UNKNOWN_POSITION_STATUSES = ("held", "unobserved")
"""Statuses of slots the ground loop did not plan (docs/trace.md): a UAV position there may be
null (not observed); such a UAV is skipped in that slot, and 14h compares its next known position
with its last known one over the slots in between."""


def control_range_m(config: Mapping[str, Any]) -> float:
    """d_th = sqrt(P_bs beta0 / (noise_w gamma_th) - (H - H_bs)^2) (14b), m; 0 if it never closes."""
    p_bs, beta0 = float(config_value(config, "P_bs")), float(config_value(config, "beta0"))
    noise, gamma = float(config_value(config, "noise_w")), float(config_value(config, "gamma_th"))
    dh = float(config_value(config, "H")) - float(config_value(config, "H_bs"))
    sq = p_bs * beta0 / (noise * gamma) - dh * dh
    return math.sqrt(sq) if sq > 0.0 else 0.0


def uplink_rate_bps(eta: float, horizontal_m: float, config: Mapping[str, Any]) -> float:
    """eta B log2(1 + Pu beta0 / (noise_w (d^2 + (H - H_bs)^2))) (eq. 1-2), bit/s."""
    bandwidth, pu = float(config_value(config, "B")), float(config_value(config, "Pu"))
    beta0, noise = float(config_value(config, "beta0")), float(config_value(config, "noise_w"))
    dh = float(config_value(config, "H")) - float(config_value(config, "H_bs"))
    snr = pu * beta0 / noise / (horizontal_m * horizontal_m + dh * dh)
    return eta * bandwidth * math.log2(1.0 + snr)


def _dist(a: Array, b: Array) -> float:
    return math.hypot(float(a[0] - b[0]), float(a[1] - b[1]))


@dataclass(frozen=True)
class _Safety:
    """The safety rule's distances (docs/model.md, "Safety"), re-derived from the config alone:
    k, e, the leg samples S, and the target's motion model (dt, kappa, P0)."""

    k: float
    e: float
    samples: int
    dt: float
    kappa: float
    P0: Array

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> _Safety | None:
        planner = cfg.get("planner") or {}
        if planner.get("safety_margin", "none") != "covariance":
            return None
        return cls(
            k=float(planner["safety_confidence_sigma"]),
            e=float(planner["tracking_margin_m"]),
            samples=int(planner["horizon"]["leg_samples"]),
            dt=float(config_value(cfg, "dt")),
            kappa=float(config_value(cfg, "kappa")),
            P0=np.asarray(config_value(cfg, "P0"), dtype=float).reshape(4, 4),
        )

    def clearance_m(self, d_safe: float, P_prev: Array) -> float:
        """D_s + k sigma + e, sigma^2 the largest eigenvalue of the predicted position covariance
        at the leg samples t = i dt / S (i = 1..S), predicted forward from P_prev [4, 4] (the
        previous slot's posterior) with the constant-velocity model."""
        worst = 0.0
        for i in range(1, self.samples + 1):
            t = i * self.dt / self.samples
            F = np.eye(4)
            F[0, 2] = F[1, 3] = t
            q = self.kappa * np.array([[t**3 / 3, t**2 / 2], [t**2 / 2, t]])
            W = np.kron(q, np.eye(2))
            P = F @ P_prev @ F.T + W
            worst = max(worst, float(np.max(np.linalg.eigvalsh(P[:2, :2]))))
        return d_safe + self.k * math.sqrt(worst) + self.e


LEG_POINTS = 400
"""Points per leg of the brute-force leg check (the planner samples S and adds chord margins)."""


def _closest_on_leg(rel0: Array, rel1: Array) -> float:
    """The smallest |r(t)| over LEG_POINTS + 1 points of the straight relative motion r0 -> r1."""
    t = np.linspace(0.0, 1.0, LEG_POINTS + 1)[:, None]
    return float(np.min(np.linalg.norm(rel0 + t * (rel1 - rel0), axis=1)))


@dataclass(frozen=True)
class _Limits:
    """The constants the constraints need, read once from the config."""

    bs_xy: Array
    start_xy: Array
    r_th: float
    n_a: int
    step_m: float
    d_safe: float
    d_th: float
    safety: _Safety | None = None

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any], safety: bool = False) -> _Limits:
        return cls(
            bs_xy=np.asarray(config_value(cfg, "bs_xy"), dtype=float).reshape(-1, 2),
            start_xy=np.asarray(config_value(cfg, "uav_start_xy"), dtype=float).reshape(-1, 2),
            r_th=float(config_value(cfg, "r_th")),
            n_a=int(config_value(cfg, "n_a")),
            step_m=float(config_value(cfg, "v_max")) * float(config_value(cfg, "dt")),
            d_safe=float(config_value(cfg, "d_safe")),
            d_th=control_range_m(cfg),
            safety=_Safety.from_config(cfg) if safety else None,
        )


def _bs_index(k: Any, n_bs: int) -> int | None:
    """k as a valid 0-based BS index, or None."""
    if isinstance(k, bool | np.bool_) or not isinstance(k, int | np.integer):
        return None
    return int(k) if 0 <= int(k) < n_bs else None


def _check_slot(
    rec: Any,
    cfg: Mapping[str, Any],
    lim: _Limits,
    prev_xy: Array,
    elapsed: Array,
    tol_m: float,
    rate_rtol: float,
    share_tol: float,
    P_prev: Array | None = None,
) -> list[Violation]:
    n, status = int(rec.slot), str(rec.status)
    q = np.asarray(rec.uav_xy_m, dtype=float).reshape(-1, 2)
    eta = np.asarray(rec.bandwidth_share, dtype=float).reshape(-1)
    assoc = list(np.asarray(rec.assoc).reshape(-1))
    n_uav, n_bs = q.shape[0], lim.bs_xy.shape[0]
    out: list[Violation] = []
    # A null position is allowed only where the slot says it was not observed.
    if status in UNKNOWN_POSITION_STATUSES:
        seen = [bool(np.all(np.isfinite(q[m]))) for m in range(n_uav)]
    else:
        seen = [True] * n_uav

    def flag(c: str, uavs: tuple[int, ...], value: float, limit: float, detail: str) -> None:
        out.append(Violation(n, c, uavs, float(value), float(limit), status, detail))

    rule = lim.safety
    e_track = 0.0 if rule is None else rule.e  # the vehicles' tracking margin
    d_sep = lim.d_safe + 2 * e_track
    d_target = lim.d_safe
    if rule is not None and P_prev is not None:
        d_target = rule.clearance_m(lim.d_safe, P_prev)

    # 14c, 14d: shares (nobody served, every BS -1 and every share 0: an operator's hold of the
    # whole fleet, docs/trace.md; there is no bandwidth to share)
    total = float(np.sum(eta))
    nobody_served = all(k == -1 for k in assoc) and total == 0.0
    if not nobody_served and not abs(total - 1.0) <= share_tol:
        flag("14c", tuple(range(n_uav)), total, 1.0, "bandwidth shares do not sum to 1")
    share_ok = [bool(-share_tol <= e <= 1.0 + share_tol) for e in eta]
    for m, e in enumerate(eta):
        if not share_ok[m]:
            flag("14d", (m,), e, 0.0 if not e >= 0.0 else 1.0, "share outside [0, 1]")
    # A vehicle outside the plan (its link lost) is marked by BS -1 and share 0: it has no link
    # to check (14a, 14f/g); it still counts for 14b-14j.
    unplanned = {m for m, k in enumerate(assoc) if k == -1 and eta[m] == 0.0}
    # 14f/g: exactly one valid BS per UAV
    bs_of = [_bs_index(k, n_bs) for k in assoc]
    for m, k in enumerate(assoc):
        if bs_of[m] is None and m not in unplanned:
            value = float(k) if isinstance(k, int | float | np.number) else math.nan
            flag("14f/g", (m,), value, n_bs - 1, f"BS index not an integer in [0, {n_bs})")
    # 14e: capacity N_a per BS
    for k in range(n_bs):
        users = tuple(m for m in range(n_uav) if bs_of[m] == k)
        if len(users) > lim.n_a:
            flag("14e", users, len(users), lim.n_a, f"BS {k} serves more than N_a UAVs")
    # 14a: rate to the associated BS (only where the share and the BS index are valid)
    for m in range(n_uav):
        k_m = bs_of[m]
        if k_m is None or not share_ok[m] or not seen[m]:
            continue
        # The position tolerance applies here too: the rate tol_m metres closer to the BS.
        dist_bs = _dist(q[m], lim.bs_xy[k_m]) + e_track
        rate = uplink_rate_bps(float(eta[m]), max(dist_bs - tol_m, 0.0), cfg)
        if not rate >= lim.r_th * (1.0 - rate_rtol):
            flag("14a", (m,), rate, lim.r_th, f"rate to BS {k_m} below R_th (bit/s)")
    # 14b: control range of the nearest BS
    for m in (m for m in range(n_uav) if seen[m]):
        nearest = min(_dist(q[m], w) for w in lim.bs_xy) + e_track
        if not nearest <= lim.d_th + tol_m:
            flag("14b", (m,), nearest, lim.d_th, "nearest BS beyond control range d_th (m)")
    # 14h: speed limit since the previous record (or the start positions)
    if prev_xy.shape == q.shape:
        for m in (m for m in range(n_uav) if seen[m]):
            allowed = lim.step_m * float(elapsed[m])
            moved = _dist(q[m], prev_xy[m])
            if not moved <= allowed + tol_m:
                flag("14h", (m,), moved, allowed, f"moved too far in {elapsed[m]:g} slot(s) (m)")
    else:
        flag("14h", tuple(range(n_uav)), n_uav, prev_xy.shape[0], "number of UAVs changed")
    # 14i: UAV-UAV separation
    for i in range(n_uav):
        for j in range(i + 1, n_uav):
            if not (seen[i] and seen[j]):
                continue
            gap = _dist(q[i], q[j])
            if not gap >= d_sep - tol_m:
                flag("14i", (i, j), gap, d_sep, "UAVs closer than D_s (+ 2 e) (m)")
            if rule is not None and prev_xy.shape == q.shape:
                start = prev_xy[i] - prev_xy[j]
                need = min(d_sep, float(np.linalg.norm(start)))
                gap = _closest_on_leg(start, q[i] - q[j])
                if not gap >= need - tol_m:
                    flag("14i", (i, j), gap, need, "UAVs closer than D_s + 2 e along the legs (m)")
    # 14j: UAV-predicted target separation
    target = np.asarray(rec.target_pred, dtype=float).reshape(-1)[:2]
    for m in (m for m in range(n_uav) if seen[m]):
        gap = _dist(q[m], target)
        if not gap >= d_target - tol_m:
            flag(
                "14j", (m,), gap, d_target, "UAV closer than the clearance to the predicted target"
            )
        if rule is not None and prev_xy.shape == q.shape:
            velocity = np.asarray(rec.target_pred, dtype=float).reshape(-1)[2:4]
            start = prev_xy[m] - (target - rule.dt * velocity)
            need = min(d_target, float(np.linalg.norm(start)))
            gap = _closest_on_leg(start, q[m] - target)
            if not gap >= need - tol_m:
                flag("14j", (m,), gap, need, "UAV closer than the clearance along its leg (m)")
    return out


def check_constraints(
    trace: Any,
    tol_m: float = 1e-6,
    *,
    rate_rtol: float = 1e-9,
    share_tol: float = 1e-9,
    safety: bool = False,
) -> list[Violation]:
    """Re-check every slot of a trace (or trace path) against (14a)-(14j) of the paper.

    Uses the config keys B, Pu, beta0, noise_w, H, H_bs, P_bs, gamma_th, r_th, n_a, v_max, dt,
    d_safe, bs_xy and uav_start_xy (ValueError names a missing one).
    - 14a  eta_m B log2(1 + Pu beta0 / noise_w / (||q_m - w_k||^2 + dH^2)) >= r_th (1 - rate_rtol)
           for the BS k the UAV is associated with; checked only where the UAV's share (14d) and
           BS index (14f/g) are valid, which are reported under their own labels instead.
    - 14b  min_k ||q_m - w_k|| <= d_th + tol_m, d_th recomputed from P_bs, beta0, ... .
    - 14c  |sum_m eta_m - 1| <= share_tol;  14d  -share_tol <= eta_m <= 1 + share_tol.
    - 14e  at most n_a UAVs per BS;  14f/g  each assoc entry is an integer in [0, K).
    - 14h  ||q_n - q_prev|| <= v_max dt s + tol_m, s = slots elapsed since the UAV's previous
           known position (the previous record, or an earlier one when it was not observed in
           between); the first is compared with uav_start_xy (the positions at slot 0) with
           s = max(1, its slot number).
    - 14i  ||q_i - q_j|| >= d_safe - tol_m;  14j  ||q_m - target_pred[:2]|| >= d_safe - tol_m.
    A UAV with BS -1 and share 0 is outside the plan (link lost): 14a and 14f/g skip it.
    In a slot the ground did not plan (UNKNOWN_POSITION_STATUSES: `held`, `unobserved`) a UAV
    with a null position was not observed: 14a, 14b and 14h-14j skip it there.
    Otherwise non-finite values count as violations. Every slot is checked whatever its status; each
    Violation carries the status so the caller decides what a non-"ok" slot may break.
    safety=True, with the trace's planner.safety_margin "covariance": the safety rule's
    distances instead (docs/model.md, "Safety"): 14j at D_s + k sigma + e with sigma from the
    covariance predicted from the previous record's P (P0 at the first), 14i at D_s + 2 e,
    14a/14b e farther from the BS, and 14i/14j along the straight legs from the previous
    positions against the target's constant-velocity prediction, checked on LEG_POINTS points
    (at least min(distance, the leg's starting distance)). Consecutive slots only.
    """
    tr = as_trace(trace)
    lim = _Limits.from_config(tr.config, safety)
    out: list[Violation] = []
    prev_xy = lim.start_xy.copy()
    prev_slot = np.zeros(prev_xy.shape[0])
    first = True
    P_prev = None if lim.safety is None else lim.safety.P0
    for rec in tr.slots:
        n = int(rec.slot)
        q = np.asarray(rec.uav_xy_m, dtype=float).reshape(-1, 2)
        elapsed = np.maximum(1.0, n - prev_slot) if first else n - prev_slot
        out += _check_slot(
            rec, tr.config, lim, prev_xy, elapsed, tol_m, rate_rtol, share_tol, P_prev
        )
        P_prev = np.asarray(rec.P, dtype=float).reshape(4, 4)
        if q.shape != prev_xy.shape:  # reported as 14h by _check_slot; start afresh
            prev_xy, prev_slot = q.copy(), np.full(q.shape[0], float(n))
        else:
            keep = np.isfinite(q).all(axis=1) | (str(rec.status) not in UNKNOWN_POSITION_STATUSES)
            prev_xy[keep], prev_slot[keep] = q[keep], n
        first = False
    return out


__all__ = [
    "CONSTRAINTS",
    "UNKNOWN_POSITION_STATUSES",
    "Violation",
    "check_constraints",
    "control_range_m",
    "uplink_rate_bps",
]
