"""GOSPA, the generalised optimal sub-pattern assignment metric between two finite sets of points.

Rahmathullah, Garcia-Fernandez and Svensson (2017): for true points X (n of them) and estimates Y
(m), cut-off c > 0, order p >= 1 and 0 < alpha <= 2,

    GOSPA^p = min over assignments of min(n, m) pairs (i, j) of
              sum d_c(x_i, y_j)^p + (c^p / alpha) |n - m|,     d_c = min(d, c),

the Euclidean distance d over the points' coordinates. With alpha = 2 the optimum splits into
the localisation of the pairs assigned within c (sum d^p), the missed true points (c^p / 2 each)
and the false estimates (c^p / 2 each): a pair at d >= c costs c^p, the same as one missed and
one false point, so it counts as both. The assignment is scipy's `linear_sum_assignment` on the
cut-off costs (exact, Jonker-Volgenant). Pure: numpy and scipy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from isac_mission.types import FloatArray, IntArray

CUTOFF_M = 10.0
"""The scenarios' default GOSPA cut-off c (m; tracker.multi.gospa_cutoff_m)."""

UNASSIGNED = -1
"""Gospa.assignment of a true point with no estimate within the cut-off."""


@dataclass(frozen=True)
class Gospa:
    """One GOSPA evaluation (units: the points' unit, m for positions; the parts in its p-th power).

    distance: GOSPA itself; localisation, missed, false: its alpha = 2 parts, which sum to
    distance^p (NaN for another alpha); n_missed, n_false: the true points with no estimate within
    c and the estimates assigned to none (counted only at alpha = 2, else -1); assignment [n]: the
    estimate index of each true point within c, or UNASSIGNED.
    """

    distance: float
    localisation: float
    missed: float
    false: float
    n_missed: int
    n_false: int
    assignment: IntArray


def gospa(
    truth: FloatArray,
    estimates: FloatArray,
    c: float = CUTOFF_M,
    p: float = 2.0,
    alpha: float = 2.0,
) -> Gospa:
    """GOSPA between the true points truth [n, d] and the estimates [m, d] (module docstring)."""
    if not c > 0:
        raise ValueError(f"GOSPA cut-off c must be > 0 (got {c})")
    if not p >= 1:
        raise ValueError(f"GOSPA order p must be >= 1 (got {p})")
    if not 0 < alpha <= 2:
        raise ValueError(f"GOSPA alpha must be in (0, 2] (got {alpha})")
    x = np.atleast_2d(np.asarray(truth, dtype=float))
    y = np.atleast_2d(np.asarray(estimates, dtype=float))
    x, y = (v.reshape(0, 2) if v.size == 0 else v for v in (x, y))
    n, m = len(x), len(y)
    assignment = np.full(n, UNASSIGNED, dtype=np.int64)
    cardinality = c**p / alpha * abs(n - m)
    if n == 0 or m == 0:
        localisation, paired = 0.0, 0
        total = cardinality
    else:
        if x.shape[1] != y.shape[1]:
            raise ValueError(f"GOSPA: truth has {x.shape[1]} coordinates, estimates {y.shape[1]}")
        d = np.linalg.norm(x[:, None] - y[None], axis=-1)
        rows, cols = linear_sum_assignment(np.minimum(d, c) ** p)
        within = d[rows, cols] < c
        assignment[rows[within]] = cols[within]
        localisation = float(np.sum(d[rows[within], cols[within]] ** p))
        paired = int(within.sum())
        total = localisation + c**p * int((~within).sum()) + cardinality
    distance = float(total ** (1 / p))
    if alpha != 2:
        nan = float("nan")
        return Gospa(distance, nan, nan, nan, -1, -1, assignment)
    half = c**p / 2
    return Gospa(
        distance,
        localisation,
        half * (n - paired),
        half * (m - paired),
        n - paired,
        m - paired,
        assignment,
    )


def mission_gospa(
    truths: list[FloatArray],
    estimates: list[FloatArray],
    c: float = 10.0,
    p: float = 2.0,
    alpha: float = 2.0,
) -> tuple[list[Gospa], float]:
    """(per-slot GOSPA, its mission mean distance) of the slots' true points truths[k] [n_k, d]
    and estimates[k] [m_k, d]."""
    if len(truths) != len(estimates):
        raise ValueError(f"{len(truths)} slots of truth but {len(estimates)} of estimates")
    per_slot = [gospa(x, y, c, p, alpha) for x, y in zip(truths, estimates, strict=True)]
    mean = float(np.mean([g.distance for g in per_slot])) if per_slot else float("nan")
    return per_slot, mean
