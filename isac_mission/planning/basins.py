"""The slot's other basins: the bandwidth band's leader moved to another UAV.

The slot problem has about one local optimum per UAV that takes most of the band (0.75-0.9 of
it: the information of a UAV grows as eta^2). Algorithm 2 starts from last slot's shares and the
polish from Algorithm 2's point, so both keep last slot's leader, while the best plan may give
the band to another UAV now as close to the target. The screen evaluates, at the plan's
waypoints, the objective with the shares of the leader and of UAV j swapped (one tr(C) per UAV,
no solve); a swap whose value is within SCREEN_RATIO of the plan's is a start for the polish.
"""

from __future__ import annotations

import numpy as np

from isac_mission.tracking.pcrb import PlanningObjective
from isac_mission.types import FloatArray

SCREEN_RATIO = 1.06
"""A swapped-leader start is polished when its tr(C) at the plan's waypoints is below
SCREEN_RATIO times the plan's tr(C)."""
MAX_STARTS = 1
"""At most this many swapped-leader starts are polished per slot (the best screened first)."""


def screen_leaders(
    xy: FloatArray, eta: FloatArray, objective: PlanningObjective, f_plan: float
) -> list[tuple[int, FloatArray]]:
    """The starts (leader j, shares [M]) worth polishing from plan (xy [M, 2], eta [M]) with
    tr(C) f_plan: eta with the leader's and UAV j's shares swapped, best screened value first,
    at most MAX_STARTS, each below SCREEN_RATIO f_plan. Deterministic (ties by UAV index)."""
    M = len(eta)
    lead = int(np.argmax(eta))
    others = [j for j in range(M) if j != lead]
    if not others or not np.isfinite(f_plan):
        return []
    etas = np.repeat(np.asarray(eta, dtype=float)[None], len(others), axis=0)
    for row, j in enumerate(others):
        etas[row, lead], etas[row, j] = eta[j], eta[lead]
    xys = np.broadcast_to(np.asarray(xy, dtype=float), (len(others), *np.shape(xy)))
    values = objective.values(xys, etas)
    order = sorted(range(len(others)), key=lambda r: (values[r], others[r]))
    out = [(others[r], etas[r]) for r in order if values[r] < SCREEN_RATIO * f_plan]
    return out[:MAX_STARTS]
