"""Monte Carlo studies over parameter grids (`isac-mission sweep CONFIG --grid GRID.yaml`).

This module is the pure-ish part: grid parsing, the job function, aggregation, CSV, plots and the
terminal table. It never imports Dask; the distributed execution is in `sweep_dask.py`.

Grid file (YAML mapping):

* ``<dotted.path>: [v1, v2, ...]`` -- a scenario key (as in config/paper.yaml) and its values,
  e.g. ``uavs.max_speed_mps: [15, 25]``. The study is the cartesian product of all such lists.
* ``uavs.count: [3, 6]`` (special) -- the number of UAVs M. M UAVs are placed evenly on a ring:
  centre = centroid of the config's ``uavs.start_xy_m``, radius = their mean distance to it
  (a quarter of the smaller area side if the config has a single UAV), the first UAV at the config's
  first start point's bearing. Cannot be combined with a ``uavs.start_xy_m`` axis.
* optional ``methods: [proposed, sd]`` (default: proposed), ``runs: 4`` (default 4),
  ``seed: 1`` (default: the config's seed), ``slots: 20`` (sets ``timing.duration_s`` to
  slots * slot_s for quick studies; default: the config's duration).

Every grid point is validated with `parse_scenario` before any work starts; an invalid point
raises ConfigError naming the grid path(s) and value(s).

Task = (grid point, method, run) -> one `run_closed_loop` with noise seed = seed + run (common
random numbers across methods and grid points) -> one `TaskRow`. Aggregates per (point, method):
location / velocity RMSE over runs with a 95 % confidence interval (Student-t interval of the mean
per-run MSE over runs, mapped through sqrt), mean tr(PCRB) parts, solve time, infeasible slots.
"""

from __future__ import annotations

import copy
import csv
import hashlib
import itertools
import json
import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, cast

import numpy as np
import yaml
from pydantic import BaseModel
from rich.table import Table

from isac_mission.config import Scenario, ScenarioFile, parse_scenario
from isac_mission.errors import ConfigError
from isac_mission.experiment.closed_loop import draw_run_noise, run_closed_loop
from isac_mission.planning.slot import METHODS, Method, SolverKit

RESERVED_KEYS = ("methods", "runs", "seed", "slots")
UAV_COUNT_PATH = "uavs.count"
DEFAULT_RUNS = 4

Value = bool | int | float | str | list[Any] | None


@dataclass(frozen=True)
class GridSpec:
    """A parsed grid file.

    axes: (dotted path, values) in file order; methods; runs >= 1; seed (None = the config's);
    slots (None = the config's duration).
    """

    axes: tuple[tuple[str, tuple[Value, ...]], ...]
    methods: tuple[Method, ...] = ("proposed",)
    runs: int = DEFAULT_RUNS
    seed: int | None = None
    slots: int | None = None

    @property
    def paths(self) -> tuple[str, ...]:
        """The swept dotted paths, in file order."""
        return tuple(p for p, _ in self.axes)

    def combinations(self) -> list[tuple[Value, ...]]:
        """The cartesian product of the axes' values (last axis varies fastest)."""
        return list(itertools.product(*(values for _, values in self.axes)))


@dataclass(frozen=True)
class GridPoint:
    """One validated grid point: its index, its swept values, its scenario and a cache key."""

    index: int
    values: tuple[tuple[str, Value], ...]
    scenario: Scenario
    key: str

    def label(self) -> str:
        """`path=value, ...` for tables and errors."""
        return ", ".join(f"{p}={_fmt_value(v)}" for p, v in self.values) or "(base)"


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
    """Metrics of one closed-loop run (units: m^2, (m/s)^2, ms; means over slots 1..N)."""

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


@dataclass(frozen=True)
class PointSummary:
    """Aggregates of one method at one grid point over its runs.

    RMSE in m and m/s with 95 % CI bounds (NaN with a single run); tr(PCRB) parts in m^2 and
    (m/s)^2; solve_median_ms = median of the per-run medians (ms).
    """

    point: int
    values: tuple[tuple[str, Value], ...]
    method: str
    runs: int
    loc_rmse: float
    loc_rmse_lo: float
    loc_rmse_hi: float
    vel_rmse: float
    vel_rmse_lo: float
    vel_rmse_hi: float
    pcrb_pos: float
    pcrb_vel: float
    solve_median_ms: float
    infeasible_slots: int
    slots: int


# ----------------------------------------------------------------------------- grid parsing


def _fmt_value(v: Value) -> str:
    return json.dumps(v) if isinstance(v, list | str) else f"{v}"


_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _coerce(v: Value) -> Value:
    """Numbers that YAML 1.1 reads as strings (`1.0e7` has no exponent sign) become numbers."""
    if isinstance(v, str) and _NUMBER.match(v.strip()):
        text = v.strip()
        return int(text) if re.fullmatch(r"[+-]?\d+", text) else float(text)
    return v


def _check_path(path: str, source: str) -> None:
    """Raise ConfigError unless `path` names a leaf of ScenarioFile (or is uavs.count)."""
    if path == UAV_COUNT_PATH:
        return
    model: type[BaseModel] = ScenarioFile
    parts = path.split(".")
    for i, part in enumerate(parts):
        field = model.model_fields.get(part)
        if field is None:
            where = ".".join(parts[:i]) or "the top level"
            known = ", ".join(sorted(model.model_fields))
            raise ConfigError(
                f"{source}: {path}: unknown key {part!r} under {where} (known: {known})"
            )
        ann = field.annotation
        is_section = isinstance(ann, type) and issubclass(ann, BaseModel)
        last = i == len(parts) - 1
        if last and is_section:
            raise ConfigError(f"{source}: {path}: is a section, not a value; name one of its keys")
        if not last:
            if not is_section:
                raise ConfigError(f"{source}: {path}: {'.'.join(parts[: i + 1])} is not a section")
            model = cast(type[BaseModel], ann)


def parse_grid(data: Any, source: str = "<grid>") -> GridSpec:
    """Validate a grid mapping (as read from YAML). Raises ConfigError with the offending key."""
    if not isinstance(data, dict) or not data:
        raise ConfigError(
            f"{source}: the grid must be a non-empty mapping of dotted paths to lists"
        )
    methods: tuple[Method, ...] = ("proposed",)
    if "methods" in data:
        raw = data["methods"]
        if isinstance(raw, str):
            raw = [m.strip() for m in raw.split(",") if m.strip()]
        if not isinstance(raw, list) or not raw or any(m not in METHODS for m in raw):
            raise ConfigError(
                f"{source}: methods: must be a non-empty list of {', '.join(METHODS)} (got {raw!r})"
            )
        methods = tuple(dict.fromkeys(cast(list[Method], raw)))
    ints: dict[str, int | None] = {}
    for key, minimum in (("runs", 1), ("seed", 0), ("slots", 1)):
        raw = data.get(key)
        if raw is not None and (not isinstance(raw, int) or isinstance(raw, bool) or raw < minimum):
            raise ConfigError(f"{source}: {key}: must be an integer >= {minimum} (got {raw!r})")
        ints[key] = raw
    axes: list[tuple[str, tuple[Value, ...]]] = []
    for path, values in data.items():
        if path in RESERVED_KEYS:
            continue
        if not isinstance(path, str):
            raise ConfigError(f"{source}: {path!r}: keys must be dotted config paths")
        _check_path(path, source)
        if not isinstance(values, list) or not values:
            raise ConfigError(
                f"{source}: {path}: must be a non-empty list of values (got {values!r})"
            )
        if path == UAV_COUNT_PATH and any(
            not isinstance(v, int) or isinstance(v, bool) or v < 1 for v in values
        ):
            raise ConfigError(f"{source}: {path}: values must be integers >= 1 (got {values!r})")
        axes.append((path, tuple(_coerce(v) for v in values)))
    paths = [p for p, _ in axes]
    if UAV_COUNT_PATH in paths and "uavs.start_xy_m" in paths:
        raise ConfigError(f"{source}: uavs.count and uavs.start_xy_m cannot both be swept")
    runs = ints["runs"]
    return GridSpec(
        axes=tuple(axes),
        methods=methods,
        runs=DEFAULT_RUNS if runs is None else runs,
        seed=ints["seed"],
        slots=ints["slots"],
    )


def load_grid(path: str | Path) -> GridSpec:
    """Read and validate a grid YAML file. Raises ConfigError."""
    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except OSError as err:
        raise ConfigError(f"{p}: cannot read: {err.strerror}") from None
    except yaml.YAMLError as err:
        raise ConfigError(f"{p}: not valid YAML: {err}") from None
    return parse_grid(data, str(p))


def ring_start_points(
    base_xy: Sequence[Sequence[float]], area_m: Sequence[float], m: int
) -> list[list[float]]:
    """[m, 2] start points (m) evenly on the ring through the base start points (uavs.count)."""
    xy = np.asarray(base_xy, dtype=float).reshape(-1, 2)
    centre = xy.mean(axis=0)
    offsets = xy - centre
    radius = float(np.mean(np.linalg.norm(offsets, axis=1)))
    if radius <= 0.0:
        radius = 0.25 * float(min(area_m))
        phase = math.pi / 2
    else:
        phase = math.atan2(float(offsets[0, 1]), float(offsets[0, 0]))
    angles = phase + 2 * math.pi * np.arange(m) / m
    pts = centre + radius * np.column_stack([np.cos(angles), np.sin(angles)])
    return [[float(round(x, 6)), float(round(y, 6))] for x, y in pts]


def _defaults(section: str) -> dict[str, Any]:
    field = ScenarioFile.model_fields[section]
    return cast(BaseModel, field.get_default(call_default_factory=True)).model_dump(mode="json")


def apply_overrides(
    base: dict[str, Any], values: Iterable[tuple[str, Value]], slots: int | None
) -> dict[str, Any]:
    """A deep copy of the config mapping with the grid point's values and the slots override."""
    data = copy.deepcopy(base)
    count: int | None = None
    for path, value in values:
        if path == UAV_COUNT_PATH:
            count = cast(int, value)
            continue
        *sections, leaf = path.split(".")
        node = data
        for part in sections:
            child = node.get(part)
            if not isinstance(child, dict):
                child = {}
                node[part] = child
            node = child
        node[leaf] = copy.deepcopy(value)
    if count is not None:
        uavs = data.setdefault("uavs", {})
        if not isinstance(uavs, dict):
            raise ConfigError("uavs: must be a mapping")
        start = uavs.get("start_xy_m", _defaults("uavs")["start_xy_m"])
        area = data.get("area", {})
        size = area.get("size_m", _defaults("area")["size_m"]) if isinstance(area, dict) else None
        uavs["start_xy_m"] = ring_start_points(start, size or (3000.0, 3000.0), count)
    if slots is not None:
        timing = data.setdefault("timing", {})
        if not isinstance(timing, dict):
            raise ConfigError("timing: must be a mapping")
        slot_s = timing.get("slot_s", _defaults("timing")["slot_s"])
        timing["duration_s"] = slots * float(slot_s)
    return data


def scenario_key(data: dict[str, Any]) -> str:
    """A stable key of a config mapping (sha1 of its canonical JSON), for per-worker caches."""
    text = json.dumps(data, sort_keys=True, default=str)
    return hashlib.sha1(text.encode()).hexdigest()[:16]


def expand_grid(base: dict[str, Any], grid: GridSpec, source: str = "<config>") -> list[GridPoint]:
    """Validate every grid point; raise one ConfigError listing every bad point."""
    points: list[GridPoint] = []
    problems: list[str] = []
    for i, combo in enumerate(grid.combinations()):
        values = tuple(zip(grid.paths, combo, strict=True))
        label = ", ".join(f"{p}={_fmt_value(v)}" for p, v in values) or "(base)"
        try:
            data = apply_overrides(base, values, grid.slots)
            s = parse_scenario(data, f"grid point {i} ({label})")
        except ConfigError as err:
            problems.append(str(err))
            continue
        points.append(GridPoint(index=i, values=values, scenario=s, key=scenario_key(data)))
    if problems:
        raise ConfigError("\n".join(problems))
    return points


def load_config_mapping(path: str | Path) -> dict[str, Any]:
    """The raw YAML mapping of a scenario file, validated once with `parse_scenario`."""
    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except OSError as err:
        raise ConfigError(f"{p}: cannot read: {err.strerror}") from None
    except yaml.YAMLError as err:
        raise ConfigError(f"{p}: not valid YAML: {err}") from None
    parse_scenario(data, str(p))
    return cast(dict[str, Any], data)


@dataclass(frozen=True)
class SweepPlan:
    """Everything a sweep will run: the grid, its validated points, the tasks and the base seed."""

    grid: GridSpec
    points: list[GridPoint]
    tasks: list[SweepTask]
    seed: int
    mission_id: str


def plan_sweep(config: str | Path, grid_file: str | Path, seed: int | None = None) -> SweepPlan:
    """Load both files and validate every grid point (raises ConfigError before any work)."""
    base = load_config_mapping(config)
    grid = load_grid(grid_file)
    points = expand_grid(base, grid, str(config))
    if seed is None:
        seed = grid.seed if grid.seed is not None else points[0].scenario.seed
    tasks = make_tasks(points, grid, seed)
    return SweepPlan(grid, points, tasks, seed, points[0].scenario.mission_id)


def make_tasks(points: Sequence[GridPoint], grid: GridSpec, seed: int) -> list[SweepTask]:
    """Every (point, method, run), runs outermost so that early results cover all points."""
    return [
        SweepTask(p.index, p.key, p.scenario, m, r, seed + r)
        for r in range(grid.runs)
        for p in points
        for m in grid.methods
    ]


# ----------------------------------------------------------------------------- the job


_KITS: dict[str, SolverKit] = {}
_MAX_KITS = 8


def kit_for(key: str, s: Scenario) -> SolverKit:
    """The SolverKit of a scenario, built once per process (a few are kept)."""
    kit = _KITS.get(key)
    if kit is None:
        if len(_KITS) >= _MAX_KITS:
            _KITS.clear()
        kit = _KITS[key] = SolverKit(s)
    return kit


_BLAS_SETTERS = (
    "openblas_set_num_threads",
    "openblas_set_num_threads64_",
    "scipy_openblas_set_num_threads",
    "scipy_openblas_set_num_threads64_",
)


def limit_blas_threads(n: int = 1) -> list[str]:
    """Set every OpenBLAS loaded in this process to `n` threads; returns their paths.

    OpenBLAS' results depend (at the 1e-8 level, which the closed loop amplifies) on its thread
    count, and Dask's nannies start workers with OMP/OPENBLAS_NUM_THREADS=1. Calling this in every
    task makes the serial run, a local cluster and any other cluster compute the same numbers (and
    avoids oversubscribing cores with BLAS threads). Linux only (/proc/self/maps); elsewhere a no-op.
    """
    import ctypes

    try:
        with open("/proc/self/maps") as f:
            libs = sorted({line.split()[-1] for line in f if "openblas" in line.lower()})
    except OSError:
        return []
    done = []
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _BLAS_SETTERS:
            setter = getattr(lib, name, None)
            if setter is not None:
                setter(ctypes.c_int(n))
                done.append(path)
                break
    return done


def run_task(task: SweepTask) -> TaskRow:
    """One closed-loop mission; returns its per-run metrics (runs in a worker process)."""
    limit_blas_threads(1)
    s = task.scenario
    res = run_closed_loop(s, task.method, draw_run_noise(s, task.seed), kit_for(task.key, s))
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


# ----------------------------------------------------------------------------- aggregation


def t_interval(samples: Sequence[float], level: float = 0.95) -> tuple[float, float, float]:
    """(mean, lo, hi): Student-t confidence interval of the mean; lo = hi = NaN for one sample."""
    from scipy import stats

    x = np.asarray(samples, dtype=float)
    mean = float(x.mean())
    if x.size < 2:
        return mean, math.nan, math.nan
    half = float(stats.t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return mean, mean - half, mean + half


def _rmse_ci(mses: Sequence[float]) -> tuple[float, float, float]:
    mean, lo, hi = t_interval(mses)
    return math.sqrt(mean), math.sqrt(max(lo, 0.0)), math.sqrt(max(hi, 0.0))


def aggregate(rows: Iterable[TaskRow], points: Sequence[GridPoint]) -> list[PointSummary]:
    """Per (grid point, method), in point then method order; rows of each group sorted by run."""
    groups: dict[tuple[int, str], list[TaskRow]] = {}
    for row in rows:
        groups.setdefault((row.point, row.method), []).append(row)
    by_index = {p.index: p for p in points}
    out: list[PointSummary] = []
    for (point, method), group in sorted(groups.items(), key=lambda kv: kv[0][0]):
        group.sort(key=lambda r: r.run)
        loc, loc_lo, loc_hi = _rmse_ci([r.loc_mse for r in group])
        vel, vel_lo, vel_hi = _rmse_ci([r.vel_mse for r in group])
        out.append(
            PointSummary(
                point=point,
                values=by_index[point].values,
                method=method,
                runs=len(group),
                loc_rmse=loc,
                loc_rmse_lo=loc_lo,
                loc_rmse_hi=loc_hi,
                vel_rmse=vel,
                vel_rmse_lo=vel_lo,
                vel_rmse_hi=vel_hi,
                pcrb_pos=float(np.mean([r.pcrb_pos for r in group])),
                pcrb_vel=float(np.mean([r.pcrb_vel for r in group])),
                solve_median_ms=float(np.median([r.solve_median_ms for r in group])),
                infeasible_slots=sum(r.infeasible_slots for r in group),
                slots=sum(r.slots for r in group),
            )
        )
    order: dict[str, int] = {m: i for i, m in enumerate(METHODS)}
    out.sort(key=lambda s: (s.point, order.get(s.method, len(order))))
    return out


# ----------------------------------------------------------------------------- output

SUMMARY_COLUMNS = [f.name for f in fields(PointSummary) if f.name != "values"]


def write_csv(summaries: Sequence[PointSummary], paths: Sequence[str], out: Path) -> Path:
    """One row per (point, method): the swept values (one column per path), then the metrics."""
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow([*paths, *SUMMARY_COLUMNS])
        for s in summaries:
            vals = dict(s.values)
            w.writerow(
                [
                    *(_fmt_value(vals[p]) for p in paths),
                    *(
                        repr(getattr(s, c)) if isinstance(getattr(s, c), float) else getattr(s, c)
                        for c in SUMMARY_COLUMNS
                    ),
                ]
            )
    return out


def write_rows_csv(rows: Sequence[TaskRow], out: Path) -> Path:
    """The per-run rows (one per task), sorted by point, method, run."""
    out.parent.mkdir(parents=True, exist_ok=True)
    names = [f.name for f in fields(TaskRow)]
    with out.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(names)
        for r in sorted(rows, key=lambda r: (r.point, r.method, r.run)):
            w.writerow(
                [repr(v) if isinstance(v, float) else v for v in map(r.__getattribute__, names)]
            )
    return out


def _numeric(values: Sequence[Value]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def plot_sweep(summaries: Sequence[PointSummary], grid: GridSpec, out_dir: Path) -> list[Path]:
    """Per swept path: location and velocity RMSE vs that value, one line per method (and per
    combination of the other swept values), with 95 % CI error bars. Returns the PNG paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for path, values in grid.axes:
        numeric = _numeric(values)
        xs_of = {
            json.dumps(v): (float(cast(float, v)) if numeric else i) for i, v in enumerate(values)
        }
        lines: dict[str, list[PointSummary]] = {}
        for s in summaries:
            others = ", ".join(f"{p}={_fmt_value(v)}" for p, v in s.values if p != path)
            lines.setdefault(s.method + (f" ({others})" if others else ""), []).append(s)
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
        for label, group in lines.items():
            group = sorted(group, key=lambda s: xs_of[json.dumps(dict(s.values)[path])])
            x = [xs_of[json.dumps(dict(s.values)[path])] for s in group]
            for ax, attr in zip(axes, ("loc_rmse", "vel_rmse"), strict=True):
                y = np.array([getattr(s, attr) for s in group])
                lo = np.array([getattr(s, attr + "_lo") for s in group])
                hi = np.array([getattr(s, attr + "_hi") for s in group])
                err = np.nan_to_num(np.vstack([y - lo, hi - y]))
                ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=label)
        for ax, title in zip(axes, ("location RMSE [m]", "velocity RMSE [m/s]"), strict=True):
            ax.set_xlabel(path)
            ax.set_ylabel(title)
            ax.grid(True, alpha=0.3)
            if not numeric:
                ax.set_xticks(range(len(values)), [_fmt_value(v) for v in values])
        axes[0].legend(fontsize=7)
        fig.suptitle(f"RMSE vs {path} (95 % t-interval over {grid.runs} runs)")
        fig.tight_layout()
        target = out_dir / f"rmse_vs_{path.replace('.', '_')}.png"
        fig.savefig(target, dpi=110)
        plt.close(fig)
        written.append(target)
    return written


def sweep_table(summaries: Sequence[PointSummary], paths: Sequence[str], title: str) -> Table:
    """Rich table: swept values (headed by the path's last key), method, RMSE with its 95 % CI,
    mean tr(PCRB) parts, infeasible slots, median planning time."""
    t = Table(title=title, caption=" / ".join(paths))
    for p in paths:
        t.add_column(p.rsplit(".", 1)[-1], justify="right")
    for col in (
        "method",
        "loc RMSE m (95% CI)",
        "vel RMSE m/s (95% CI)",
        "PCRB pos",
        "PCRB vel",
        "infeas.",
        "plan ms",
    ):
        t.add_column(col, justify="left" if col == "method" else "right")
    for s in summaries:
        vals = dict(s.values)
        t.add_row(
            *(_fmt_value(vals[p]) for p in paths),
            s.method,
            f"{s.loc_rmse:.3g} ({s.loc_rmse_lo:.3g}-{s.loc_rmse_hi:.3g})",
            f"{s.vel_rmse:.3g} ({s.vel_rmse_lo:.3g}-{s.vel_rmse_hi:.3g})",
            f"{s.pcrb_pos:.3g}",
            f"{s.pcrb_vel:.3g}",
            f"{s.infeasible_slots}/{s.slots}",
            f"{s.solve_median_ms:.1f}",
        )
    return t
