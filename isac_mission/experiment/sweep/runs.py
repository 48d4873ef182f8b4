"""The work of a sweep: tasks (grid point x method x run), one closed-loop run per task, serially.

Task = (grid point, method, run) -> one mission of the offline loop (`closed_loop.fly_offline`)
with the run's noise (`tracking/factory.draw_noise`, seed = seed + run: common random numbers
across methods and grid points) -> one `TaskRow`. A point of the single-target path flies
`run_closed_loop` (its labelled target's errors and bound, and its GOSPA); a point of the
multi-target path (docs/model.md, "Several targets") flies `multi_target_loop.run_multi_target`
and keeps the run's `multi_target_metrics.RunFigures`, as `simulate` does. `run_task` is also
what the Dask workers run (`cluster.run_dask`); this module never imports Dask.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from isac_mission.config import Scenario
from isac_mission.config.live_settings import LiveSettings
from isac_mission.errors import ConfigError
from isac_mission.experiment.closed_loop import run_closed_loop
from isac_mission.experiment.multi_target_loop import run_multi_target
from isac_mission.experiment.multi_target_metrics import RunFigures, run_figures
from isac_mission.experiment.sweep.grid import (
    GridPoint,
    GridSpec,
    expand_grid,
    load_config_mapping,
    load_grid,
)
from isac_mission.model.run_noise import MultiTargetNoise
from isac_mission.nlp_cache import CompiledNlpCache
from isac_mission.planning.multi_target import check_multi_target_method
from isac_mission.planning.slot import Method, SolverKit
from isac_mission.tracking.factory import draw_noise, keep_out_tracks, labelled
from isac_mission.tracking.gospa import mission_gospa


@dataclass(frozen=True)
class SweepTask:
    """One unit of work: run `run` of `method` at grid point `point` (noise seed `seed`)."""

    point: int
    key: str
    scenario: Scenario
    method: Method
    run: int
    seed: int


@dataclass(frozen=True)
class TaskRow:
    """Metrics of one closed-loop run (units: m^2, (m/s)^2, ms, m; means over slots 1..N).

    loc_mse, vel_mse, pcrb_pos, pcrb_vel: the labelled target's squared errors and tr(PCRB)
    parts (NaN on a multi-target point: no one target); gospa_m: the mission-mean GOSPA (m, the
    scenario's cut-off tracker.multi.gospa_cutoff_m, p = 2; one target: min(error, c) as
    montecarlo.MethodSummary.gospa_m); figures: a multi-target run's figures (None on the
    single-target path; not a runs.csv column).
    """

    point: int
    method: str
    run: int
    seed: int
    loc_mse: float
    vel_mse: float
    pcrb_pos: float
    pcrb_vel: float
    solve_median_ms: float
    infeasible_slots: int
    slots: int
    gospa_m: float = math.nan
    figures: RunFigures | None = field(default=None, compare=False)


@dataclass(frozen=True)
class SweepPlan:
    """Everything a sweep will run: the grid, its validated points, the tasks and the base seed."""

    grid: GridSpec
    points: list[GridPoint]
    tasks: list[SweepTask]
    seed: int
    mission_id: str


def plan_sweep(
    config: str | Path,
    grid_file: str | Path,
    seed: int | None = None,
    live: LiveSettings | None = None,
) -> SweepPlan:
    """Load both files and validate every grid point (raises ConfigError before any work, a
    method that plans for one target on a point of the multi-target path included:
    `planning.multi_target.check_multi_target_method`); with `live`, every point plans with the
    live settings (config/live_settings.py) applied to its scenario, as
    `simulate --live-settings` does."""
    base = load_config_mapping(config)
    grid = load_grid(grid_file)
    points = expand_grid(base, grid, str(config))
    check_methods(points, grid.methods, str(config))
    if live is not None:
        points = [replace(p, scenario=live.apply(p.scenario), key=f"live:{p.key}") for p in points]
    if seed is None:
        seed = grid.seed if grid.seed is not None else points[0].scenario.seed
    tasks = make_tasks(points, grid, seed)
    return SweepPlan(grid, points, tasks, seed, points[0].scenario.mission_id)


def check_methods(points: Sequence[GridPoint], methods: Sequence[Method], source: str) -> None:
    """Raise ConfigError (one line, the first refusal) if a method cannot plan a point: on the
    multi-target path, a method that plans for one target (the registry's max_targets)."""
    for p in points:
        if labelled(p.scenario):
            continue
        for m in methods:
            try:
                check_multi_target_method(m)
            except ConfigError as err:
                raise ConfigError(f"{source}: grid point {p.index}: {err}") from None


def make_tasks(points: Sequence[GridPoint], grid: GridSpec, seed: int) -> list[SweepTask]:
    """Every (point, method, run), runs outermost so that early results cover all points."""
    return [
        SweepTask(p.index, p.key, p.scenario, m, r, seed + r)
        for r in range(grid.runs)
        for p in points
        for m in grid.methods
    ]


_KITS: dict[str, SolverKit] = {}
_MAX_KITS = 8


def kit_for(key: str, s: Scenario) -> SolverKit:
    """The SolverKit of a scenario, built once per process (a few are kept), with the keep-out
    points its tracker needs (`tracking/factory.keep_out_tracks`: none for the labelled target)."""
    kit = _KITS.get(key)
    if kit is None:
        if len(_KITS) >= _MAX_KITS:
            _KITS.clear()
        kit = _KITS[key] = SolverKit(
            s, n_keep_out=keep_out_tracks(s), ipopt=CompiledNlpCache(compile="never")
        )
    return kit


def clear_kits() -> None:
    """Forget this process's SolverKits (benchmarks time the cvxpy compilations again)."""
    _KITS.clear()


def limit_blas_threads(n: int = 1) -> list[str]:
    """Set every BLAS library loaded in this process to `n` threads; returns their file paths.

    OpenBLAS' results depend (at the 1e-8 level, which the closed loop amplifies) on its thread
    count, and Dask's nannies start workers with OMP/OPENBLAS_NUM_THREADS=1. Calling this in every
    task makes the serial run, a local cluster and any other cluster compute the same numbers (and
    avoids oversubscribing cores with BLAS threads). The libraries are found and set by
    threadpoolctl (OpenBLAS, MKL, BLIS, FlexiBLAS); the limit stays until changed again.
    """
    from threadpoolctl import ThreadpoolController

    blas = ThreadpoolController().select(user_api="blas")
    blas.limit(limits=n)
    return sorted({str(lib.filepath) for lib in blas.lib_controllers})


def run_task(task: SweepTask) -> TaskRow:
    """One closed-loop mission; returns its per-run metrics (runs in a worker process)."""
    limit_blas_threads(1)
    s = task.scenario
    kit = kit_for(task.key, s)
    noise = draw_noise(s, task.seed)
    if isinstance(noise, MultiTargetNoise):
        return _multi_target_row(task, noise, kit)
    res = run_closed_loop(s, task.method, noise, kit)
    _, gospa_m = mission_gospa(
        list(res.true[:, None, :2]), list(res.est[:, None, :2]), s.multi_tracker.gospa_cutoff_m
    )
    err = res.est - res.true  # [N, 4]
    pos_tr = np.trace(res.pcrb[:, :2, :2], axis1=-2, axis2=-1)
    vel_tr = np.trace(res.pcrb[:, 2:, 2:], axis1=-2, axis2=-1)
    return TaskRow(
        point=task.point,
        method=task.method,
        run=task.run,
        seed=task.seed,
        loc_mse=float(np.mean(np.sum(err[:, :2] ** 2, axis=1))),
        vel_mse=float(np.mean(np.sum(err[:, 2:] ** 2, axis=1))),
        pcrb_pos=float(pos_tr.mean()),
        pcrb_vel=float(vel_tr.mean()),
        solve_median_ms=float(np.median(res.solve_s) * 1e3),
        infeasible_slots=sum(st != "ok" for st in res.status),
        slots=len(res.status),
        gospa_m=gospa_m,
    )


def _multi_target_row(task: SweepTask, noise: MultiTargetNoise, kit: SolverKit) -> TaskRow:
    """One mission of the multi-target path (`run_multi_target`) and its figures
    (`multi_target_metrics.run_figures`, the scenario's GOSPA cut-off), as `simulate` has them."""
    s = task.scenario
    run = run_multi_target(s, task.method, noise, kit)
    figures = run_figures(run, s.multi_tracker.gospa_cutoff_m)
    reports = [o.plan.report for o in run.slots]
    return TaskRow(
        point=task.point,
        method=task.method,
        run=task.run,
        seed=task.seed,
        loc_mse=math.nan,
        vel_mse=math.nan,
        pcrb_pos=math.nan,
        pcrb_vel=math.nan,
        solve_median_ms=float(np.median([r.solve_s for r in reports]) * 1e3),
        infeasible_slots=sum(r.status != "ok" for r in reports),
        slots=len(reports),
        gospa_m=float(figures.gospa_m.mean()),
        figures=figures,
    )


def run_serial(
    tasks: Sequence[SweepTask], on_done: Callable[[TaskRow], None] | None = None
) -> list[TaskRow]:
    """Every task in this process, in order (the reference the Dask runner must match)."""
    rows = []
    for t in tasks:
        row = run_task(t)
        rows.append(row)
        if on_done is not None:
            on_done(row)
    return rows
