"""The work of a sweep: tasks (grid point x method x run), one closed-loop run per task, serially.

Task = (grid point, method, run) -> one mission flown as `simulate` flies a run
(experiment/runs.py: `fly_outcomes` with the run's noise, seed = seed + run: common random
numbers across methods and grid points; `mission_run` measures it) -> one `TaskRow`. Every row
has its run's tracks' GOSPA (track_metrics.py); a run with a labelled track
(`runs.has_labelled_track`) has that track's errors and bound, a run without one keeps its
tracks' `RunFigures`, as `simulate` reports each. `run_task` is also what the Dask workers run
(`cluster.run_dask`); this module never imports Dask.
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
from isac_mission.experiment.closed_loop import SlotOutcome
from isac_mission.experiment.runs import MissionRun, fly_outcomes, mission_run, scenario_kit
from isac_mission.experiment.sweep.grid import (
    GridPoint,
    GridSpec,
    expand_grid,
    load_config_mapping,
    load_grid,
)
from isac_mission.experiment.track_metrics import RunFigures
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method
from isac_mission.planning.tracks import method_problem


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

    loc_mse, vel_mse, pcrb_pos, pcrb_vel: the labelled track's squared errors and tr(PCRB)
    parts (NaN for a run without a labelled track); gospa_m: the mission-mean GOSPA of the run's
    confirmed tracks (m, the scenario's cut-off tracker.multi.gospa_cutoff_m, p = 2; one
    labelled track: min(error, c) as montecarlo.MethodSummary.gospa_m); figures: the tracks'
    figures of a run without a labelled track (None for a run with one; not a runs.csv column).
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
    method that cannot plan for a point's tracks included: `check_methods`); with `live`, every
    point plans with the live settings (config/live_settings.py) applied to its scenario, as
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
    """Raise ConfigError (one line, the first refusal) if a method cannot plan for a point's
    tracks (`planning/tracks.method_problem`, as `simulate` refuses it)."""
    for p in points:
        for m in methods:
            problem = method_problem(p.scenario, m)
            if problem is not None:
                raise ConfigError(f"{source}: grid point {p.index}: {problem}")


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
    """The SolverKit of a grid point's scenario (`runs.scenario_kit`, as `simulate` builds it),
    built once per process (a few are kept)."""
    kit = _KITS.get(key)
    if kit is None:
        if len(_KITS) >= _MAX_KITS:
            _KITS.clear()
        kit = _KITS[key] = scenario_kit(s)
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
    outcomes = fly_outcomes(s, task.method, task.seed, kit_for(task.key, s))
    return task_row(task, mission_run(s, task.method, task.seed, outcomes), outcomes)


def task_row(task: SweepTask, run: MissionRun, outcomes: Sequence[SlotOutcome]) -> TaskRow:
    """The row of a task's run (`TaskRow`): its labelled track's columns when it had one, its
    tracks' GOSPA in every case, its planner's times and statuses from the slots flown."""
    labelled = run.labelled
    nan = math.nan
    loc_mse = vel_mse = pcrb_pos = pcrb_vel = nan
    if labelled is not None:
        err = labelled.est - labelled.true  # [N, 4]
        loc_mse = float(np.mean(np.sum(err[:, :2] ** 2, axis=1)))
        vel_mse = float(np.mean(np.sum(err[:, 2:] ** 2, axis=1)))
        pcrb_pos = float(np.trace(labelled.pcrb[:, :2, :2], axis1=-2, axis2=-1).mean())
        pcrb_vel = float(np.trace(labelled.pcrb[:, 2:, 2:], axis1=-2, axis2=-1).mean())
    return TaskRow(
        point=task.point,
        method=task.method,
        run=task.run,
        seed=task.seed,
        loc_mse=loc_mse,
        vel_mse=vel_mse,
        pcrb_pos=pcrb_pos,
        pcrb_vel=pcrb_vel,
        solve_median_ms=float(np.median(run.solve_s) * 1e3),
        infeasible_slots=sum(o.plan.report.status != "ok" for o in outcomes),
        slots=len(outcomes),
        gospa_m=float(run.tracking.gospa_m.mean()),
        figures=run.tracking if labelled is None else None,
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
