"""Monte Carlo over runs x methods with common random numbers, for any number of targets, and the
labelled target's summary.

Run r of every method uses the noise drawn from seed + r (experiment/runs.py flies, measures
and traces one run; `run_monte_carlo` runs them all, in one process pool). Every run has its
tracks' figures (GOSPA and each target's error against its track's bound:
experiment/track_metrics.py, summed up by `summarize_tracking`); a run with a labelled track has
its per-slot arrays too, summed up by `summarize`. Metrics of the labelled target (docs/model.md, "Metrics"):
location RMSE = sqrt(mean over runs and slots 1..N of ||p_hat - p||^2), velocity likewise; mean
tr(PCRB) position and velocity parts over the same runs and slots (the first slots, where the
bound is still large, dominate that mean, so the position part over the second half of the
mission is reported too); the efficiency ratio
E||p_hat - p||^2 / tr(PCRB_pos) over slots 2..N. The phase figures (the whole
tr(PCRB) over slots 11..N and over the second half, RMSEs over slots 2..N) are the `*_from11`,
`pcrb_late` and `*_from2` fields (experiment/comparison.py, which also gives every method's
reduction against `proposed` with paired bootstrap intervals).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.experiment.closed_loop import RunResult
from isac_mission.experiment.comparison import pooled, run_figures
from isac_mission.experiment.runs import (
    MissionRun,
    fly_run,
    labelled_arrays,
    outcome_record,
    trace_path,
)
from isac_mission.planning.slot import Method
from isac_mission.planning.tracks import method_problem
from isac_mission.tracking.gospa import CUTOFF_M, mission_gospa

__all__ = [
    "PAPER_REDUCTIONS",
    "MethodSummary",
    "MissionRun",
    "outcome_record",
    "reduction_pct",
    "run_monte_carlo",
    "summarize",
    "trace_path",
]

# The paper's Section IV: % reduction of the proposed method's location and velocity error
# against SD, ABA and CRB-criterion.
PAPER_REDUCTIONS: dict[str, tuple[float, float]] = {
    "sd": (61.1, 59.9),
    "aba": (22.8, 29.1),
    "crb": (9.0, 12.0),
}


@dataclass(frozen=True)
class MethodSummary:
    """Aggregates of one method over all runs (units: m^2, (m/s)^2, m, m/s, ms).

    pcrb_pos, pcrb_vel, loc_rmse, vel_rmse: over slots 1..N; pcrb_pos_late: position part over
    the second half; pcrb_from11 / pcrb_late: whole tr(PCRB) over slots 11..N (NaN when N < 11) /
    the second half; loc_rmse_from2, vel_rmse_from2: over slots 2..N, pooled over runs.
    """

    method: str
    runs: int
    pcrb_pos: float
    pcrb_vel: float
    pcrb_pos_late: float
    loc_rmse: float
    vel_rmse: float
    efficiency: float
    solve_median_ms: float
    solve_p95_ms: float
    infeasible_slots: int
    slots: int
    pcrb_from11: float = math.nan
    pcrb_late: float = math.nan
    loc_rmse_from2: float = math.nan
    vel_rmse_from2: float = math.nan
    fallbacks: dict[str, int] = field(default_factory=dict)
    """Slots whose method's answer was not flown, by kind (SolveReport.fallback)."""
    gospa_m: float = math.nan
    """The mission-mean GOSPA (m) of the estimated target position, over slots 1..N and runs
    (tracking/gospa.py; one target: min(error, c)), the figure reported for several targets."""

    @property
    def pcrb_total(self) -> float:
        return self.pcrb_pos + self.pcrb_vel


def summarize(
    runs: Sequence[MissionRun | RunResult], gospa_cutoff_m: float = CUTOFF_M
) -> MethodSummary:
    """Aggregate the labelled track of one method's runs (GOSPA with cut-off gospa_cutoff_m, m);
    ValueError for a run without one (runs.labelled_arrays)."""
    results = [labelled_arrays(r) for r in runs]
    err = np.array([r.est - r.true for r in results])  # [R, N, 4]
    C = np.array([r.pcrb for r in results])  # [R, N, 4, 4]
    loc_se = np.sum(err[..., :2] ** 2, axis=-1)
    vel_se = np.sum(err[..., 2:] ** 2, axis=-1)
    pos_tr = np.trace(C[..., :2, :2], axis1=-2, axis2=-1)
    vel_tr = np.trace(C[..., 2:, 2:], axis1=-2, axis2=-1)
    solve_ms = np.concatenate([r.solve_s for r in results]) * 1e3
    figures = pooled(run_figures(results))
    return MethodSummary(
        method=results[0].method,
        runs=len(results),
        pcrb_pos=float(pos_tr.mean()),
        pcrb_vel=float(vel_tr.mean()),
        pcrb_pos_late=float(pos_tr[:, pos_tr.shape[1] // 2 :].mean()),
        loc_rmse=float(np.sqrt(loc_se.mean())),
        vel_rmse=float(np.sqrt(vel_se.mean())),
        efficiency=float(loc_se[:, 1:].mean() / pos_tr[:, 1:].mean()),
        solve_median_ms=float(np.median(solve_ms)),
        solve_p95_ms=float(np.percentile(solve_ms, 95)),
        infeasible_slots=sum(s != "ok" for r in results for s in r.status),
        slots=sum(len(r.status) for r in results),
        pcrb_from11=figures["pcrb_from11"],
        pcrb_late=figures["pcrb_late"],
        loc_rmse_from2=figures["loc_rmse"],
        vel_rmse_from2=figures["vel_rmse"],
        fallbacks=dict(Counter(f for r in results for f in r.fallback if f)),
        gospa_m=float(
            np.mean(
                [
                    mission_gospa(
                        list(r.true[:, None, :2]), list(r.est[:, None, :2]), gospa_cutoff_m
                    )[1]
                    for r in results
                ]
            )
        ),
    )


def reduction_pct(proposed: float, benchmark: float) -> float:
    """How much lower the proposed value is than the benchmark's, in %."""
    return 100.0 * (benchmark - proposed) / benchmark


def run_monte_carlo(
    s: Scenario,
    methods: Sequence[Method],
    runs: int,
    seed: int,
    trace_dir: Path | None = None,
    progress: Callable[[str, int], None] | None = None,
    workers: int = 1,
) -> dict[str, list[MissionRun]]:
    """Every method on runs 0..runs-1 (noise seed = seed + run); results per method by run.

    ConfigError, before any run, for a method that cannot plan for the scenario's tracks
    (planning/tracks.method_problem). progress(method, run) is called as each (method, run)
    finishes. workers > 1 runs them in separate processes (results are identical: each run's
    noise depends on its seed only).
    """
    for m in methods:
        problem = method_problem(s, m)
        if problem is not None:
            raise ConfigError(problem)
    if trace_dir is not None:
        trace_dir.mkdir(parents=True, exist_ok=True)
    jobs = [(m, r) for r in range(runs) for m in methods]
    out: dict[str, dict[int, MissionRun]] = {m: {} for m in methods}
    if workers <= 1:
        for m, r in jobs:
            out[m][r] = fly_run(s, m, r, seed, trace_dir)
            if progress:
                progress(m, r)
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(fly_run, s, m, r, seed, trace_dir): (m, r) for m, r in jobs}
            for fut in as_completed(futures):
                m, r = futures[fut]
                out[m][r] = fut.result()
                if progress:
                    progress(m, r)
    return {m: [out[m][r] for r in range(runs)] for m in methods}
