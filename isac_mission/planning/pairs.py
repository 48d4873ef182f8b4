"""Which UAV pairs the horizon NLP must keep apart: the pairs within reach, in a banded order.

A pair's separation rows (14i at every leg sample of the horizon) can only bind if the two UAVs
can come within the rows' distance inside the horizon. Every plan that meets the horizon's other
rows keeps each UAV m within reach_m[m] of its start (the step rows 14h and, on the vehicle
model, the velocity control points; docs/model.md, "The pairs within reach"),
so the rows of a pair whose start distance is at least their distance plus both reaches are
implied by the rest: dropping them changes neither the problem's feasible set nor its solutions.

An NLP's structure is fixed when it is built, and the pairs within reach change from slot to
slot; so the horizon is built for a few *bands*: the rows of the NLP's UAV slots a < b with
b - a <= band. Each slot the fleet is put in an order (reverse Cuthill-McKee on the graph of the
pairs within reach) in which every such pair is within the band of the smallest NLP that covers it.

Pure: numpy and scipy.sparse.csgraph only.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import reverse_cuthill_mckee

from isac_mission.types import BoolArray, FloatArray, IntArray

REACH_SLACK_M = 1.0
"""Added to a pair's distance when deciding it is out of reach: covers the solver's tolerance on
the rows (CAP_FEASIBILITY_TOL, about 1e-4 m here) many times over."""


def pair_bands(n_uavs: int, band: int) -> tuple[int, ...]:
    """The bands of the horizon NLPs built for a fleet of n_uavs (n_uavs - 1: every pair):
    the full problem alone when twice the band reaches it (it would save few rows); else the
    band and, as the wider problem, twice the band when that is at most half the full one and
    the full problem otherwise (twice the band would have most of its rows)."""
    full = max(n_uavs - 1, 0)
    if 2 * band >= full:
        return (full,)
    return (band, 2 * band if 4 * band <= full else full)


def band_pair_count(n_uavs: int, band: int) -> int:
    """The pairs (a, b), 0 <= a < b < n_uavs, b - a <= band."""
    band = min(band, max(n_uavs - 1, 0))
    return band * n_uavs - band * (band + 1) // 2


def horizon_reach_m(
    prev_velocity_mps: FloatArray, v_max_mps: float, dt_s: float, length: int
) -> FloatArray:
    """reach [M], m: the farthest each UAV gets from its start within `length` slots on a plan
    that keeps the horizon's rows. On the first leg its speed stays within the larger of its
    start speed (prev_velocity_mps [M, 2]; a vehicle may start faster than the planner's V_max)
    and V_max (the leg's velocity is a Bezier curve of control points within those), after that
    within V_max (14h keeps every slot's step within V_max dt)."""
    speed = np.linalg.norm(np.asarray(prev_velocity_mps, dtype=float), axis=1)
    first = np.maximum(speed, v_max_mps) * dt_s
    return np.asarray(first + (length - 1) * v_max_mps * dt_s)


def pairs_within_reach(prev_xy_m: FloatArray, reach_m: FloatArray, clearance_m: float) -> BoolArray:
    """within [M, M], symmetric, False on the diagonal: the UAVs at prev_xy_m [M, 2] that can
    come closer than clearance_m (+ REACH_SLACK_M) when each moves at most reach_m [M]."""
    xy = np.asarray(prev_xy_m, dtype=float)
    distance = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    reach = np.asarray(reach_m, dtype=float)
    within = distance < clearance_m + REACH_SLACK_M + reach[:, None] + reach[None]
    np.fill_diagonal(within, False)
    return np.asarray(within)


def bandwidth(within: BoolArray, order: IntArray) -> int:
    """The largest |position(i) - position(j)| over the pairs within [M, M] when UAV order[a]
    takes slot a (0 without pairs)."""
    position = np.empty(len(order), dtype=int)
    position[np.asarray(order)] = np.arange(len(order))
    i, j = np.nonzero(within)
    return int(np.max(np.abs(position[i] - position[j]))) if len(i) else 0


def banded_order(within: BoolArray) -> tuple[IntArray, int]:
    """(order [M], its bandwidth): an order of the UAVs in which the pairs within [M, M] are
    close (reverse Cuthill-McKee), or the identity when it is not narrower."""
    n = len(within)
    identity = np.arange(n)
    if not np.any(within):
        return identity, 0
    order = np.asarray(reverse_cuthill_mckee(csr_matrix(within), symmetric_mode=True), dtype=int)
    narrow, plain = bandwidth(within, order), bandwidth(within, identity)
    return (order, narrow) if narrow < plain else (identity, plain)
