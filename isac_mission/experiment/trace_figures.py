"""The per-run figures of experiment/comparison.py, from traces: the same figures for a live run
(`run`'s trace) and an offline one (`simulate`'s traces), so that the two can be compared.

Per trace, over its slot records (slot 1 first): `pcrb` (mean tr(PCRB) over the slots),
`pcrb_from11`, `pcrb_late`, and `loc_mse`, `vel_mse` (mean over slots 2..N of the squared
position and velocity errors against the trace's truth, m^2 and m^2/s^2). A live slot whose
truth did not reach the ground loop has no error: it is left out of the means (`truth_missing`
counts such slots), and a trace with no truth at all has NaN errors.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from isac_mission.experiment.comparison import FROM_SLOT
from isac_mission.records import Trace
from isac_mission.types import FloatArray


def trace_figures(traces: Sequence[Trace]) -> dict[str, FloatArray]:
    """Per-trace figures [R] (the keys of comparison.FIGURES, and `truth_missing`)."""
    out: dict[str, list[float]] = {
        k: [] for k in ("pcrb", "pcrb_from11", "pcrb_late", "loc_mse", "vel_mse", "truth_missing")
    }
    for trace in traces:
        slots = sorted(trace.slots, key=lambda r: r.slot)
        tr = np.array([r.pcrb_trace for r in slots], dtype=float)
        n = len(tr)
        out["pcrb"].append(float(tr.mean()) if n else math.nan)
        out["pcrb_from11"].append(float(tr[FROM_SLOT - 1 :].mean()) if n >= FROM_SLOT else math.nan)
        out["pcrb_late"].append(float(tr[n // 2 :].mean()) if n else math.nan)
        loc: list[float] = []
        vel: list[float] = []
        missing = 0
        for r in slots[1:]:
            if r.target_true is None:
                missing += 1
                continue
            e = np.asarray(r.target_est, dtype=float) - np.asarray(r.target_true, dtype=float)
            loc.append(float(e[0] ** 2 + e[1] ** 2))
            vel.append(float(e[2] ** 2 + e[3] ** 2))
        out["loc_mse"].append(float(np.mean(loc)) if loc else math.nan)
        out["vel_mse"].append(float(np.mean(vel)) if vel else math.nan)
        out["truth_missing"].append(float(missing))
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}
