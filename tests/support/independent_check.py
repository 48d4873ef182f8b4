"""An independent re-checker of a run trace: the paper's constraints and the PCRB recursion.

Written from the paper (eq. 1-14) and DESIGN.md with numpy only. It deliberately does not import
isac_mission.model, isac_mission.tracking or isac_mission.planning: its point is to catch the
library's own mistakes, so every formula here is re-derived and coded independently (in a
different style: per-UAV loops, a square-root information update instead of the library's
scaled inverse). It reads the trace through `isac_mission.records.read_trace` only when
given a path; otherwise any object with `.config` (dict) and `.slots` (records with the trace's
field names, see DESIGN.md "Trace") will do.

Units: SI throughout (m, s, W, Hz, bit/s, linear ratios); positions [M, 2] in the scenario plane;
target state [x, y, vx, vy] in m and m/s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple, Protocol

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

CONSTRAINTS = ("14a", "14b", "14c", "14d", "14e", "14f/g", "14h", "14i", "14j")
"""The labels check_constraints uses (14e is the N_a capacity; 14f and 14g are checked together:
each UAV must name exactly one valid BS)."""


class _TraceLike(Protocol):
    @property
    def config(self) -> dict[str, Any]: ...

    @property
    def slots(self) -> Sequence[Any]: ...


def _as_trace(trace: Any) -> _TraceLike:
    if isinstance(trace, str | Path):
        from isac_mission.records import read_trace  # the file format only

        return read_trace(trace)
    return trace  # type: ignore[no-any-return]


def _get(config: Mapping[str, Any], key: str) -> Any:
    if key not in config:
        raise ValueError(f"trace config lacks {key!r}, which the check needs")
    return config[key]


# --------------------------------------------------------------------------------------------
# Constraints (14a)-(14j)


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


def control_range_m(config: Mapping[str, Any]) -> float:
    """d_th = sqrt(P_bs beta0 / (noise_w gamma_th) - (H - H_bs)^2) (14b), m; 0 if it never closes."""
    p_bs, beta0 = float(_get(config, "P_bs")), float(_get(config, "beta0"))
    noise, gamma = float(_get(config, "noise_w")), float(_get(config, "gamma_th"))
    dh = float(_get(config, "H")) - float(_get(config, "H_bs"))
    sq = p_bs * beta0 / (noise * gamma) - dh * dh
    return math.sqrt(sq) if sq > 0.0 else 0.0


def uplink_rate_bps(eta: float, horizontal_m: float, config: Mapping[str, Any]) -> float:
    """eta B log2(1 + Pu beta0 / (noise_w (d^2 + (H - H_bs)^2))) (eq. 1-2), bit/s."""
    bandwidth, pu = float(_get(config, "B")), float(_get(config, "Pu"))
    beta0, noise = float(_get(config, "beta0")), float(_get(config, "noise_w"))
    dh = float(_get(config, "H")) - float(_get(config, "H_bs"))
    snr = pu * beta0 / noise / (horizontal_m * horizontal_m + dh * dh)
    return eta * bandwidth * math.log2(1.0 + snr)


def _dist(a: Array, b: Array) -> float:
    return math.hypot(float(a[0] - b[0]), float(a[1] - b[1]))


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

    @classmethod
    def from_config(cls, cfg: Mapping[str, Any]) -> _Limits:
        return cls(
            bs_xy=np.asarray(_get(cfg, "bs_xy"), dtype=float).reshape(-1, 2),
            start_xy=np.asarray(_get(cfg, "uav_start_xy"), dtype=float).reshape(-1, 2),
            r_th=float(_get(cfg, "r_th")),
            n_a=int(_get(cfg, "n_a")),
            step_m=float(_get(cfg, "v_max")) * float(_get(cfg, "dt")),
            d_safe=float(_get(cfg, "d_safe")),
            d_th=control_range_m(cfg),
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
    elapsed: int,
    tol_m: float,
    rate_rtol: float,
    share_tol: float,
) -> list[Violation]:
    n, status = int(rec.slot), str(rec.status)
    q = np.asarray(rec.uav_xy, dtype=float).reshape(-1, 2)
    eta = np.asarray(rec.eta, dtype=float).reshape(-1)
    assoc = list(np.asarray(rec.assoc).reshape(-1))
    n_uav, n_bs = q.shape[0], lim.bs_xy.shape[0]
    out: list[Violation] = []

    def flag(c: str, uavs: tuple[int, ...], value: float, limit: float, detail: str) -> None:
        out.append(Violation(n, c, uavs, float(value), float(limit), status, detail))

    # 14c, 14d: shares
    total = float(np.sum(eta))
    if not abs(total - 1.0) <= share_tol:
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
        if k_m is None or not share_ok[m]:
            continue
        # The position tolerance applies here too: the rate tol_m metres closer to the BS.
        rate = uplink_rate_bps(float(eta[m]), max(_dist(q[m], lim.bs_xy[k_m]) - tol_m, 0.0), cfg)
        if not rate >= lim.r_th * (1.0 - rate_rtol):
            flag("14a", (m,), rate, lim.r_th, f"rate to BS {k_m} below R_th (bit/s)")
    # 14b: control range of the nearest BS
    for m in range(n_uav):
        nearest = min(_dist(q[m], w) for w in lim.bs_xy)
        if not nearest <= lim.d_th + tol_m:
            flag("14b", (m,), nearest, lim.d_th, "nearest BS beyond control range d_th (m)")
    # 14h: speed limit since the previous record (or the start positions)
    if prev_xy.shape == q.shape:
        allowed = lim.step_m * elapsed
        for m in range(n_uav):
            moved = _dist(q[m], prev_xy[m])
            if not moved <= allowed + tol_m:
                flag("14h", (m,), moved, allowed, f"moved too far in {elapsed} slot(s) (m)")
    else:
        flag("14h", tuple(range(n_uav)), n_uav, prev_xy.shape[0], "number of UAVs changed")
    # 14i: UAV-UAV separation
    for i in range(n_uav):
        for j in range(i + 1, n_uav):
            gap = _dist(q[i], q[j])
            if not gap >= lim.d_safe - tol_m:
                flag("14i", (i, j), gap, lim.d_safe, "UAVs closer than D_s (m)")
    # 14j: UAV-predicted target separation
    target = np.asarray(rec.target_pred, dtype=float).reshape(-1)[:2]
    for m in range(n_uav):
        gap = _dist(q[m], target)
        if not gap >= lim.d_safe - tol_m:
            flag("14j", (m,), gap, lim.d_safe, "UAV closer than D_s to the predicted target (m)")
    return out


def check_constraints(
    trace: Any,
    tol_m: float = 1e-6,
    *,
    rate_rtol: float = 1e-9,
    share_tol: float = 1e-9,
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
    - 14h  ||q_n - q_prev|| <= v_max dt s + tol_m, s = slots elapsed since the previous record;
           the first record is compared with uav_start_xy (the positions at slot 0) with
           s = max(1, its slot number).
    - 14i  ||q_i - q_j|| >= d_safe - tol_m;  14j  ||q_m - target_pred[:2]|| >= d_safe - tol_m.
    A UAV with BS -1 and share 0 is outside the plan (link lost): 14a and 14f/g skip it.
    Non-finite values count as violations. Every slot is checked whatever its status; each
    Violation carries the status so the caller decides what a non-"ok" slot may break.
    """
    tr = _as_trace(trace)
    lim = _Limits.from_config(tr.config)
    out: list[Violation] = []
    prev_xy, prev_slot = lim.start_xy, None
    for rec in tr.slots:
        n = int(rec.slot)
        elapsed = max(1, n) if prev_slot is None else n - prev_slot
        out += _check_slot(rec, tr.config, lim, prev_xy, elapsed, tol_m, rate_rtol, share_tol)
        prev_xy, prev_slot = np.asarray(rec.uav_xy, dtype=float).reshape(-1, 2), n
    return out


# --------------------------------------------------------------------------------------------
# The PCRB recursion (Tichavsky), re-derived


def measurement(x: Array, uav_xy: Array) -> Array:
    """h(x) [2M] (eq. 6): ranges ||p - q_m|| (m) then radial velocities (p - q_m).v / d_m (m/s)."""
    q = np.asarray(uav_xy, dtype=float).reshape(-1, 2)
    n_uav = q.shape[0]
    out = np.empty(2 * n_uav)
    for m in range(n_uav):
        dx, dy = x[0] - q[m, 0], x[1] - q[m, 1]
        d = math.hypot(dx, dy)
        out[m] = d
        out[n_uav + m] = (dx * x[2] + dy * x[3]) / d
    return out


def jacobian(x: Array, uav_xy: Array) -> Array:
    """dh/dx [2M, 4] at x [4], written out by hand.

    Range row m:    [dx/d, dy/d, 0, 0].
    Velocity row m: with s = dx vx + dy vy (so v_m = s / d):
      dv/dx = vx/d - s dx/d^3,  dv/dy = vy/d - s dy/d^3,  dv/dvx = dx/d,  dv/dvy = dy/d.
    """
    q = np.asarray(uav_xy, dtype=float).reshape(-1, 2)
    n_uav = q.shape[0]
    jac = np.zeros((2 * n_uav, 4))
    for m in range(n_uav):
        dx, dy = x[0] - q[m, 0], x[1] - q[m, 1]
        d = math.hypot(dx, dy)
        s = dx * x[2] + dy * x[3]
        jac[m, 0], jac[m, 1] = dx / d, dy / d
        row = n_uav + m
        jac[row, 0] = x[2] / d - s * dx / d**3
        jac[row, 1] = x[3] / d - s * dy / d**3
        jac[row, 2], jac[row, 3] = dx / d, dy / d
    return jac


def cv_model(dt: float, kappa: float) -> tuple[Array, Array]:
    """(F, W) [4, 4] of eq. 3-4 for state order [x, y, vx, vy]."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    w = np.zeros((4, 4))
    for i in (0, 1):
        w[i, i] = dt**3 / 3.0
        w[i, i + 2] = w[i + 2, i] = dt**2 / 2.0
        w[i + 2, i + 2] = dt
    return f, kappa * w


def bound_update(c_prev: Array, f: Array, w: Array, h: Array, r_diag: Array) -> tuple[Array, Array]:
    """One slot of the recursion from the previous PCRB matrix C_{n-1} = J_{n-1}^-1 [4, 4].

    C_pred = F C_{n-1} F^T + W (well conditioned: W > 0); J_pred = C_pred^-1 via its Cholesky
    factor L; J_n = J_pred + H^T R^-1 H summed entry by entry (rows whose variance is not finite
    are dropped: a missing measurement carries no information). C_n = J_n^-1 is computed in
    square-root information form: the QR factor U of [R^-1/2 H; L^-1] has U^T U = J_n, so
    C_n = U^-1 U^-T. Unlike the covariance-form update C_pred - C_pred H^T S^-1 H C_pred, whose
    subtraction loses every digit of a 1e-20 m^2 position variance, this keeps C_n accurate entry
    by entry even when range variances are ~1e-20 (the literal eq. 8). Returns (C_n, J_n).
    """
    c_pred = f @ c_prev @ f.T + w
    c_pred = 0.5 * (c_pred + c_pred.T)
    chol = np.linalg.cholesky(c_pred)
    chol_inv = np.linalg.solve(chol, np.eye(4))
    j_pred = chol_inv.T @ chol_inv
    r = np.asarray(r_diag, dtype=float).reshape(-1)
    keep = np.isfinite(r)
    if np.any(r[keep] <= 0.0):
        raise ValueError(f"measurement variances must be > 0 (got {r.tolist()})")
    hk, rk = h[keep], r[keep]
    j_meas = np.zeros((4, 4))
    for row, var in zip(hk, rk, strict=True):
        j_meas += np.outer(row, row) / var
    j_n = j_pred + j_meas
    stacked = np.vstack([hk / np.sqrt(rk)[:, None], chol_inv])
    upper = np.linalg.qr(stacked, mode="r")
    upper_inv = np.linalg.solve(upper, np.eye(4))
    c_n = upper_inv @ upper_inv.T
    return 0.5 * (c_n + c_n.T), 0.5 * (j_n + j_n.T)


class PcrbPoint(NamedTuple):
    """The recomputed bound at one slot: tr(J^-1) (m^2 + m^2/s^2) and J [4, 4]."""

    slot: int
    pcrb_trace: float
    J: Array


def _recompute(trace: _TraceLike) -> list[tuple[PcrbPoint, Array]]:
    cfg = trace.config
    f, w = cv_model(float(_get(cfg, "dt")), float(_get(cfg, "kappa")))
    c = np.asarray(_get(cfg, "P0"), dtype=float).reshape(4, 4)  # C_0 = P0, i.e. J_0 = P0^-1
    out: list[tuple[PcrbPoint, Array]] = []
    for rec in trace.slots:
        x = np.asarray(rec.target_pred, dtype=float).reshape(4)
        h = jacobian(x, np.asarray(rec.uav_xy, dtype=float))
        try:
            c, j = bound_update(c, f, w, h, np.asarray(rec.r_diag, dtype=float))
        except (np.linalg.LinAlgError, ValueError):
            c = j = np.full((4, 4), np.nan)
        out.append((PcrbPoint(int(rec.slot), float(np.trace(c)), j), c))
    return out


def recompute_pcrb(trace: Any) -> list[PcrbPoint]:
    """Re-derive every slot's bound from the trace alone (trace object or path).

    J_0 = inv(config P0); per record in file order: J_pred = inv(F J_{n-1}^-1 F^T + W) with
    F, W from config dt and kappa (eq. 3-4), J_n = J_pred + H^T R^-1 H with H = dh/dx at the
    logged target_pred and uav_xy and R = diag(r_diag) (null/NaN rows dropped). Returns
    (slot, tr(J_n^-1), J_n) per record; NaN where a step is undefined (bad variances, a UAV on
    the predicted target).
    """
    return [point for point, _ in _recompute(_as_trace(trace))]


def compare_pcrb(trace: Any, rtol: float = 1e-6) -> list[str]:
    """Mismatches between the logged and the recomputed bound, one message per slot and field.

    pcrb_trace is compared relatively: |logged - ours| <= rtol |ours|. J is compared after
    Jacobi scaling by our diagonal: |J_log[i,j] - J[i,j]| / sqrt(J[i,i] J[j,j]) <= rtol for
    every entry. That is the relative comparison when J is well conditioned and stays meaningful
    when it is not (range variances ~1e-20 give cond(J) ~1e17, where comparing J^-1 entries
    relatively would test only rounding), because each entry of J is a sum of terms bounded by
    the geometric mean of the diagonal terms (Cauchy-Schwarz), so the sum is accurate to that
    scale.
    """
    tr = _as_trace(trace)
    msgs: list[str] = []
    for rec, (point, _c) in zip(tr.slots, _recompute(tr), strict=True):
        n = point.slot
        logged = float(rec.pcrb_trace) if rec.pcrb_trace is not None else math.nan
        ours = point.pcrb_trace
        if not abs(logged - ours) <= rtol * abs(ours):
            rel = abs(logged - ours) / abs(ours) if ours else math.inf
            msgs.append(
                f"slot {n}: pcrb_trace logged {logged:.12g} vs recomputed {ours:.12g} "
                f"(relative difference {rel:.3g} > rtol {rtol:g})"
            )
        j_log = np.asarray(rec.J, dtype=float).reshape(4, 4)
        j_ours = point.J
        scale = np.sqrt(np.outer(np.diag(j_ours), np.diag(j_ours)))
        with np.errstate(invalid="ignore", divide="ignore"):
            err = np.abs(j_log - j_ours) / scale
        err = np.where(np.isfinite(err), err, np.inf)
        worst = np.unravel_index(int(np.argmax(err)), err.shape)
        if not float(err[worst]) <= rtol:
            i, k = int(worst[0]), int(worst[1])
            msgs.append(
                f"slot {n}: J[{i},{k}] logged {j_log[i, k]:.12g} vs recomputed {j_ours[i, k]:.12g} "
                f"(difference / sqrt(J[{i},{i}] J[{k},{k}]) = {float(err[worst]):.3g} > rtol {rtol:g})"
            )
    return msgs


__all__ = [
    "CONSTRAINTS",
    "PcrbPoint",
    "Violation",
    "bound_update",
    "check_constraints",
    "compare_pcrb",
    "control_range_m",
    "cv_model",
    "jacobian",
    "measurement",
    "recompute_pcrb",
    "uplink_rate_bps",
]
