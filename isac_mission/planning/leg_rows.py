"""The SCA subproblem's eq. 22-23 rows at every leg sample (the safety rule, docs/model.md).

With planner.safety_margin on, (P1.1.2) keeps the clearances at each sampled instant tau of the
straight legs (planning/legs.py): a sample's position tau q + (1 - tau) q_prev is affine in the
waypoint q, so each distance constraint |tau q + (1 - tau) q_prev - u(tau)| >= R is linearised at
q^r as eq. 23 is: 2 tau r^T q >= R^2 - |r|^2 + 2 tau r^T q^r, r = tau q^r + (1 - tau) q_prev - u.
At tau = 1 these are eq. 22 and 23 themselves. Pure: numpy only.
"""

from __future__ import annotations

import numpy as np

from isac_mission.planning.feasibility import SlotConstraints
from isac_mission.types import FloatArray, IntArray


def leg_rows(
    origin: SlotConstraints,
    pairs: IntArray,
    n_keep_out: int,
    lin: FloatArray,
    shift: FloatArray,
    solver_margin_m: float,
) -> dict[str, FloatArray]:
    """The Parameter values target_normal [S (1 + L) M, 2], target_rhs, pair_normal [S P, 2]
    and pair_rhs (row order: sample, then point or pair, then UAV) linearised at lin [M, 2],
    in coordinates shifted by `shift` [2]; pairs [P, 2] the UAV index pairs; R the per-sample
    clearances (SlotConstraints.sample_clearances_m) plus solver_margin_m."""
    M = origin.scenario.M
    c_target, c_keep, c_pairs = origin.sample_clearances_m()  # [S, M], [S, M, K], [S, P]
    prev = origin.prev_xy - shift
    target = origin.target_points() - shift  # [S, 2]
    keep = np.zeros((0, 2)) if not n_keep_out else np.asarray(origin.keep_out_xy) - shift
    lin_rows = np.tile(lin, (1 + len(keep), 1))
    normals, rhs, pair_normals, pair_rhs = [], [], [], []
    for f, tau in enumerate(origin.leg_fractions):
        points = np.vstack([target[f][None], keep])  # [1 + L, 2]
        at = tau * lin + (1.0 - tau) * prev  # the sample's position at the linearisation point
        r = np.tile(at, (len(points), 1)) - np.repeat(points, M, axis=0)
        radii2 = (np.concatenate([c_target[f], c_keep[f].T.ravel()]) + solver_margin_m) ** 2
        normals.append(2.0 * tau * r)
        rhs.append(radii2 - np.sum(r**2, axis=1) + 2.0 * tau * np.sum(r * lin_rows, axis=1))
        if len(pairs):
            i, j = pairs[:, 0], pairs[:, 1]
            rp = at[i] - at[j]
            pair_normals.append(2.0 * tau * rp)
            pair_rhs.append(
                (c_pairs[f] + solver_margin_m) ** 2
                - np.sum(rp**2, axis=1)
                + 2.0 * tau * np.sum(rp * (lin[i] - lin[j]), axis=1)
            )
    out = {"target_normal": np.vstack(normals), "target_rhs": np.concatenate(rhs)}
    if len(pairs):
        out["pair_normal"] = np.vstack(pair_normals)
        out["pair_rhs"] = np.concatenate(pair_rhs)
    return out
