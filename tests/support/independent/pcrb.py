"""The PCRB recursion (Tichavsky), re-derived: h(x), its Jacobian, the CV model, the bound's
square-root information update, and the comparison with a trace's logged J and tr(PCRB).

Units: SI throughout; target state [x, y, vx, vy] in m and m/s (see the package doc).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from tests.support.independent.common import Array, TraceLike, as_trace, config_value


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


def posterior_trace(prior_information: Array, x: Array, uav_xy: Array, r_diag: Array) -> float:
    """tr((J_pred + H^T R^-1 H)^-1) of one target at state x [4] measured from uav_xy [M, 2]
    with variances r_diag [2M] (m^2 then m^2/s^2; inf or NaN: no measurement): its bound after
    one slot's measurements, H this module's own Jacobian."""
    H = jacobian(x, uav_xy)
    r = np.asarray(r_diag, dtype=float)
    with np.errstate(divide="ignore"):
        info = np.where(np.isfinite(r), 1.0 / r, 0.0)
    J = np.asarray(prior_information, dtype=float) + H.T @ (info[:, None] * H)
    return float(np.trace(np.linalg.inv(J)))


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


def _recompute(trace: TraceLike) -> list[tuple[PcrbPoint, Array]]:
    cfg = trace.config
    f, w = cv_model(float(config_value(cfg, "dt")), float(config_value(cfg, "kappa")))
    c = np.asarray(config_value(cfg, "P0"), dtype=float).reshape(4, 4)  # C_0 = P0, i.e. J_0 = P0^-1
    out: list[tuple[PcrbPoint, Array]] = []
    for rec in trace.slots:
        x = np.asarray(rec.target_pred, dtype=float).reshape(4)
        h = jacobian(x, np.asarray(rec.uav_xy_m, dtype=float))
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
    return [point for point, _ in _recompute(as_trace(trace))]


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
    tr = as_trace(trace)
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
    "PcrbPoint",
    "bound_update",
    "compare_pcrb",
    "cv_model",
    "jacobian",
    "measurement",
    "recompute_pcrb",
]
