"""Per-run figures of a Monte Carlo and every method's reduction against `proposed`, with paired
bootstrap 95 % intervals over runs (experiment/bootstrap.py).

Figures (docs/model.md, "Metrics"), per run r over its slots (slot 1 = index 0):
- `pcrb`: mission-mean tr(PCRB) = mean over slots 1..N of tr(C_n), C_n = J_n^-1 (m^2 + (m/s)^2);
- `pcrb_from11`: the same over slots 11..N (NaN when N < 11), the tracking phase after the
  initial transient;
- `pcrb_late`: the same over the second half, slots floor(N/2)+1..N;
- `loc_mse`, `vel_mse`: mean over slots 2..N of ||p_hat - p||^2 (m^2) and ||v_hat - v||^2;
  the RMSE pooled over runs is sqrt(mean over runs), every run having the same slots.
Each method against `proposed` (the reference) is a % change, 100 (other / proposed - 1) for the
means and 100 (sqrt(other / proposed) - 1) for the RMSEs (negative: the method is lower, better,
than `proposed`; bootstrap.change_pct), the runs paired by seed: `simulate` prints it
(CHANGES, `changes_against_reference`). summary.json's `against_proposed` keeps the reductions,
the same numbers with the opposite sign (FIGURES, `reductions_against_baseline`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from isac_mission.experiment.bootstrap import (
    Interval,
    PairedStatistic,
    change_of_means,
    change_of_rms,
    paired_bootstrap,
    reduction_of_means,
    reduction_of_rms,
)
from isac_mission.experiment.closed_loop import RunResult
from isac_mission.experiment.runs import MissionRun, labelled_arrays
from isac_mission.types import FloatArray

FROM_SLOT = 11
"""First slot of the tracking-phase mean `pcrb_from11` (1-based)."""

FIGURES: dict[str, PairedStatistic] = {
    "pcrb": reduction_of_means,
    "pcrb_from11": reduction_of_means,
    "pcrb_late": reduction_of_means,
    "loc_mse": reduction_of_rms,
    "vel_mse": reduction_of_rms,
}
"""The per-run figures and the statistic that turns two methods' values into a % reduction
(summary.json's `against_proposed`)."""

CHANGES: dict[str, PairedStatistic] = {
    "pcrb": change_of_means,
    "pcrb_from11": change_of_means,
    "pcrb_late": change_of_means,
    "loc_mse": change_of_rms,
    "vel_mse": change_of_rms,
}
"""The same figures and the statistic that turns two methods' values into a % change (the tables)."""

BASELINE = "proposed"

NEEDS_TWO_RUNS = "a paired bootstrap interval needs at least 2 runs"
"""Why a comparison of one run has an estimate and no interval."""


def change_convention(reference: str) -> str:
    """The sign convention every comparison table of `simulate` states in its title, against the
    method labelled `reference`."""
    return f"% change = 100 (method / {reference} - 1), negative = lower (better) than {reference}"


@dataclass(frozen=True)
class Change:
    """One figure of one method against the reference, in % (bootstrap.change_pct's sign).

    `estimate` is None when the figure has no value (slots 11..N of a mission shorter than 11
    slots); `interval` is the paired bootstrap interval, None when it cannot be formed, and
    `missing` then says why."""

    estimate: float | None
    interval: Interval | None
    missing: str | None = None


def run_figures(runs: Sequence[MissionRun | RunResult]) -> dict[str, FloatArray]:
    """Per-run figures [R] of one method's runs' labelled track (keys of FIGURES, see the module
    docstring); ValueError for a run without one (runs.labelled_arrays)."""
    results = [labelled_arrays(r) for r in runs]
    err = np.array([r.est - r.true for r in results])  # [R, N, 4]
    C = np.array([r.pcrb for r in results])  # [R, N, 4, 4]
    tr = np.trace(C, axis1=-2, axis2=-1)  # [R, N]
    n = tr.shape[1]
    from11 = (
        tr[:, FROM_SLOT - 1 :].mean(axis=1) if n >= FROM_SLOT else np.full(len(results), math.nan)
    )
    return {
        "pcrb": tr.mean(axis=1),
        "pcrb_from11": from11,
        "pcrb_late": tr[:, n // 2 :].mean(axis=1),
        "loc_mse": np.sum(err[:, 1:, :2] ** 2, axis=-1).mean(axis=1),
        "vel_mse": np.sum(err[:, 1:, 2:] ** 2, axis=-1).mean(axis=1),
    }


def pooled(figures: Mapping[str, FloatArray]) -> dict[str, float]:
    """The figures over all runs: means, and RMSEs (m, m/s) for the two MSEs."""
    mean = {k: float(np.mean(v)) for k, v in figures.items()}
    return {
        "pcrb": mean["pcrb"],
        "pcrb_from11": mean["pcrb_from11"],
        "pcrb_late": mean["pcrb_late"],
        "loc_rmse": math.sqrt(mean["loc_mse"]),
        "vel_rmse": math.sqrt(mean["vel_mse"]),
    }


def changes_against_reference(
    figures_by_method: Mapping[str, Mapping[str, FloatArray]],
    *,
    reference: str = BASELINE,
    seed: int = 0,
    level: float = 0.95,
) -> dict[str, dict[str, Change]]:
    """Per method other than `reference`: each figure's % change against it (CHANGES), with its
    paired bootstrap interval over runs when there are two runs or more. {} when `reference` was
    not run."""
    if reference not in figures_by_method:
        return {}
    ref = figures_by_method[reference]
    out: dict[str, dict[str, Change]] = {}
    for method, figs in figures_by_method.items():
        if method == reference:
            continue
        row: dict[str, Change] = {}
        for key, statistic in CHANGES.items():
            r, o = np.asarray(ref[key], dtype=float), np.asarray(figs[key], dtype=float)
            if not (np.all(np.isfinite(r)) and np.all(np.isfinite(o))):
                why = f"slots 11..N need N >= {FROM_SLOT}" if key == "pcrb_from11" else "not finite"
                row[key] = Change(None, None, why)
            elif r.size < 2:
                row[key] = Change(float(statistic(r, o)), None, NEEDS_TWO_RUNS)
            else:
                iv = paired_bootstrap(r, o, statistic, level=level, seed=seed)
                row[key] = Change(iv.estimate, iv)
        out[method] = row
    return out


def reductions_against_baseline(
    figures_by_method: Mapping[str, Mapping[str, FloatArray]],
    *,
    baseline: str = BASELINE,
    seed: int = 0,
    level: float = 0.95,
) -> dict[str, dict[str, Interval | None]]:
    """Per method other than `baseline`: each figure's % reduction against it (FIGURES: the
    negative of `changes_against_reference`'s change; summary.json's `against_proposed`), paired
    bootstrap interval over runs (None when it cannot be formed: one run, or a figure NaN such as
    slots 11..N of a short mission). {} when `baseline` was not run."""
    if baseline not in figures_by_method:
        return {}
    base = figures_by_method[baseline]
    out: dict[str, dict[str, Interval | None]] = {}
    for method, figs in figures_by_method.items():
        if method == baseline:
            continue
        row: dict[str, Interval | None] = {}
        for key, statistic in FIGURES.items():
            b, o = base[key], figs[key]
            ok = b.size >= 2 and bool(np.all(np.isfinite(b)) and np.all(np.isfinite(o)))
            row[key] = paired_bootstrap(b, o, statistic, level=level, seed=seed) if ok else None
        out[method] = row
    return out
