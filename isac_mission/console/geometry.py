"""Numbers the page draws, computed once on the server side: the 2-sigma ellipse of a 2 x 2
position covariance and the position and velocity parts of tr(J^-1)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def ellipse_2sigma(P: Sequence[Sequence[float]] | np.ndarray) -> dict[str, float] | None:
    """The 2-sigma ellipse of the position block P[:2, :2] (m^2) of a covariance: semi-axes
    `a_m` >= `b_m` (m) and the angle `angle_rad` of the major axis from +x (east) towards +y
    (north). None when the block is not a finite symmetric positive semi-definite matrix."""
    block = np.asarray(P, dtype=float)[:2, :2]
    if not np.all(np.isfinite(block)):
        return None
    sym = 0.5 * (block + block.T)
    values, vectors = np.linalg.eigh(sym)
    if values[0] < -1e-9 * max(1.0, abs(values[1])):
        return None
    lo, hi = (max(float(v), 0.0) for v in values)
    major = vectors[:, 1]
    return {
        "a_m": 2.0 * math.sqrt(hi),
        "b_m": 2.0 * math.sqrt(lo),
        "angle_rad": math.atan2(float(major[1]), float(major[0])),
    }


def pcrb_parts(J: Sequence[Sequence[float]] | np.ndarray) -> tuple[float, float] | None:
    """(position part m^2, velocity part m^2/s^2) of tr(J^-1) for a 4 x 4 information matrix
    over [x, y, vx, vy]; None when J is singular or not finite."""
    info = np.asarray(J, dtype=float)
    if info.shape != (4, 4) or not np.all(np.isfinite(info)):
        return None
    try:
        bound = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return None
    diag = np.diag(bound)
    if not np.all(np.isfinite(diag)):
        return None
    return float(diag[0] + diag[1]), float(diag[2] + diag[3])


def position_error_m(
    estimate: Sequence[float] | np.ndarray, truth: Sequence[float] | np.ndarray | None
) -> float | None:
    """|estimate[:2] - truth[:2]| (m), None without a finite truth."""
    if truth is None:
        return None
    e, t = np.asarray(estimate, dtype=float)[:2], np.asarray(truth, dtype=float)[:2]
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(t))):
        return None
    return float(np.hypot(*(e - t)))
