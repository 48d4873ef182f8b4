"""The line search of Algorithm 1, shared by the position and the bandwidth subproblems.

Pure: numpy only.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from isac_mission.types import BoolArray, FloatArray


@dataclass(frozen=True)
class DescentResult:
    """Outcome of a descent search: best point, its objective, iterations, whether it is feasible."""

    point: FloatArray
    value: float
    iterations: int
    feasible: bool


def line_search(
    start: FloatArray,
    target: FloatArray,
    step: float,
    values: Callable[[FloatArray], FloatArray],
    feasible: Callable[[FloatArray], BoolArray],
) -> tuple[FloatArray, float] | None:
    """argmin over omega in {0, step, ..., 1} of f(start + omega (target - start)) among feasible
    candidates; None if none is feasible. start/target are arrays of any equal shape."""
    omegas = np.unique(np.append(np.arange(0.0, 1.0, step), 1.0))
    cands = start[None] + omegas.reshape((-1,) + (1,) * start.ndim) * (target - start)[None]
    ok = feasible(cands)
    if not np.any(ok):
        return None
    f = values(cands)
    f = np.where(ok, f, np.inf)
    i = int(np.argmin(f))
    if not np.isfinite(f[i]):
        return None
    return cands[i], float(f[i])
