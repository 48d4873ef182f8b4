"""The per-run figures of experiment/comparison.py, from traces: the same figures for a live run
(`run`'s trace) and an offline one (`simulate`'s traces), so that the two can be compared.

Per trace, over its slot records (slot 1 first): `pcrb` (mean tr(PCRB) over the slots),
`pcrb_from11`, `pcrb_late`, and `loc_mse`, `vel_mse` (mean over slots 2..N of the squared
position and velocity errors against the trace's truth, m^2 and m^2/s^2). A live slot whose
truth did not reach the ground loop has no error: it is left out of the means (`truth_missing`
counts such slots), and a trace with no truth at all has NaN errors.

Beside them, for live against offline (bench/live_compare.py): `loc_mse_from11`,
`vel_mse_from11` (the same over slots 11..N, the tracking phase), `step_m`, `step_from11_m`
(the mean step per UAV per slot, |uav_xy_n - uav_xy_{n-1}| in m, over slots 2..N and 11..N;
UAVs with an unknown position in either slot left out) and `fallbacks` (slots whose method's
answer was not flown, the records' `fallback`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from isac_mission.experiment.comparison import FROM_SLOT
from isac_mission.records import SlotRecord, Trace
from isac_mission.types import FloatArray

TRACE_FIGURES = (
    *("pcrb", "pcrb_from11", "pcrb_late", "loc_mse", "vel_mse", "truth_missing"),
    *("loc_mse_from11", "vel_mse_from11", "step_m", "step_from11_m", "fallbacks"),
)
"""The keys of trace_figures' result (see the module doc)."""


def trace_figures(traces: Sequence[Trace]) -> dict[str, FloatArray]:
    """Per-trace figures [R] (the keys of comparison.FIGURES, and `truth_missing`)."""
    out: dict[str, list[float]] = {k: [] for k in TRACE_FIGURES}
    for trace in traces:
        slots = sorted(trace.slots, key=lambda r: r.slot)
        tr = np.array([r.pcrb_trace for r in slots], dtype=float)
        n = len(tr)
        out["pcrb"].append(float(tr.mean()) if n else math.nan)
        out["pcrb_from11"].append(float(tr[FROM_SLOT - 1 :].mean()) if n >= FROM_SLOT else math.nan)
        out["pcrb_late"].append(float(tr[n // 2 :].mean()) if n else math.nan)
        loc: list[float] = []
        vel: list[float] = []
        from11: list[bool] = []
        missing = 0
        for r in slots[1:]:
            if r.target_true is None:
                missing += 1
                continue
            e = np.asarray(r.target_est, dtype=float) - np.asarray(r.target_true, dtype=float)
            loc.append(float(e[0] ** 2 + e[1] ** 2))
            vel.append(float(e[2] ** 2 + e[3] ** 2))
            from11.append(r.slot >= FROM_SLOT)
        late = np.asarray(from11, dtype=bool)
        out["loc_mse"].append(_mean(np.asarray(loc)))
        out["vel_mse"].append(_mean(np.asarray(vel)))
        out["loc_mse_from11"].append(_mean(np.asarray(loc)[late]) if loc else math.nan)
        out["vel_mse_from11"].append(_mean(np.asarray(vel)[late]) if vel else math.nan)
        out["truth_missing"].append(float(missing))
        step, step_slot = _steps(slots)
        out["step_m"].append(_mean(step))
        out["step_from11_m"].append(_mean(step[step_slot >= FROM_SLOT]))
        out["fallbacks"].append(float(sum(bool(r.fallback) for r in slots)))
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def _mean(values: FloatArray) -> float:
    return float(np.mean(values)) if values.size else math.nan


def _steps(slots: Sequence[SlotRecord]) -> tuple[FloatArray, FloatArray]:
    """Per-UAV steps (m) between consecutive slots (a null position leaves its UAV out), and
    the slot each step ends in."""
    steps: list[float] = []
    ends: list[int] = []
    for prev, rec in itertools.pairwise(slots):
        if rec.slot != prev.slot + 1:
            continue
        d = np.linalg.norm(np.asarray(rec.uav_xy_m) - np.asarray(prev.uav_xy_m), axis=1)
        known = d[np.isfinite(d)]
        steps.extend(known.tolist())
        ends.extend([rec.slot] * known.size)
    return np.asarray(steps, dtype=float), np.asarray(ends, dtype=np.int64)
