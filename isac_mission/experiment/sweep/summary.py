"""Aggregates of a sweep and their outputs: per-point summaries, the two CSV files, the table.

Aggregates per (point, method): location / velocity RMSE over runs with a 95 % confidence
interval (Student-t interval of the mean per-run MSE over runs, mapped through sqrt), mean
tr(PCRB) parts, solve time, infeasible slots, the mission-mean GOSPA with its 95 % t-interval
over runs; on a point whose runs had no labelled track, the figures `simulate` reports for their
tracks (`track_metrics.summarize_tracking` of the runs' figures).

sweep.csv, one row per (point, method): the swept values (one column per path), then
`point, method, runs, loc_rmse, loc_rmse_lo, loc_rmse_hi, vel_rmse, vel_rmse_lo, vel_rmse_hi,
pcrb_pos, pcrb_vel, solve_median_ms, infeasible_slots, slots` (the labelled track's: NaN on a
point without one), then `gospa_m, gospa_m_lo, gospa_m_hi`, and, when a point of the sweep has
its tracks' figures, `MULTI_TARGET_COLUMNS` and two columns per target i (its index in
`targets:`): `target<i>_rmse_m`, `target<i>_bound_m2` (empty on a point of a labelled track). NaN
(`nan`): no value (one run: no interval; a target never followed: no RMSE). runs.csv: one row per
task, `TaskRow`'s numbers (its `figures` left out).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
from rich.table import Table

from isac_mission.experiment.sweep.grid import GridPoint, Value, fmt_value
from isac_mission.experiment.sweep.runs import TaskRow
from isac_mission.experiment.track_metrics import TrackingSummary, summarize_tracking
from isac_mission.planning.registry import METHODS


@dataclass(frozen=True)
class PointSummary:
    """Aggregates of one method at one grid point over its runs.

    RMSE in m and m/s with 95 % CI bounds (NaN with a single run); tr(PCRB) parts in m^2 and
    (m/s)^2; solve_median_ms = median of the per-run medians (ms); these are the labelled
    track's, NaN on a point without one. gospa_m: mean over runs of the mission-mean GOSPA (m)
    with its 95 % t-interval (the lower bound clipped at 0; NaN with a single run). tracking: the tracks' figures over the
    runs of a point without a labelled track (`track_metrics.summarize_tracking`; None with one).
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
    gospa_m: float = math.nan
    gospa_m_lo: float = math.nan
    gospa_m_hi: float = math.nan
    tracking: TrackingSummary | None = None


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
        gospa, gospa_lo, gospa_hi = t_interval([r.gospa_m for r in group])
        gospa_lo = max(gospa_lo, 0.0)  # GOSPA >= 0 (NaN stays NaN), as the RMSE's bound
        figures = [r.figures for r in group if r.figures is not None]
        tracking = summarize_tracking(figures) if figures else None
        if tracking is not None:
            gospa = tracking.gospa_m  # the same mean, as the tracks report has it
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
                gospa_m=gospa,
                gospa_m_lo=gospa_lo,
                gospa_m_hi=gospa_hi,
                tracking=tracking,
            )
        )
    order: dict[str, int] = {m: i for i, m in enumerate(METHODS)}
    out.sort(key=lambda s: (s.point, order.get(s.method, len(order))))
    return out


SUMMARY_COLUMNS = [f.name for f in fields(PointSummary) if f.name not in ("values", "tracking")]
"""sweep.csv's columns after the swept values, every sweep (module docstring)."""

MULTI_TARGET_COLUMNS = [
    "gospa_localisation_m2",
    "gospa_missed_m2",
    "gospa_false_m2",
    "id_switches",
    "runs_with_false_tracks",
    "longest_false_run",
    "confirmation_delay_median",
    "confirmation_delay_max",
    "never_confirmed",
]
"""sweep.csv's columns of a point's tracks' figures (`TrackingSummary`), after
SUMMARY_COLUMNS: the GOSPA parts (m^2, means over slots and runs), ID switches per run, the share
of runs with a confirmed false track, the longest run of slots a false track stayed confirmed,
the confirmation delays' median and largest (slots from the first slot three UAVs saw a target
to its confirmation, over targets and runs; NaN: none confirmed), the targets seen but never
confirmed; then `target_columns`."""


def target_columns(n_targets: int) -> list[str]:
    """Each target's location RMSE (m) and mean tr(PCRB_pos) (m^2) over the slots a confirmed
    track followed it, pooled over runs: `target<i>_rmse_m`, `target<i>_bound_m2`."""
    return [f"target{i}_{what}" for i in range(n_targets) for what in ("rmse_m", "bound_m2")]


def tracking_cells(x: TrackingSummary) -> list[float | int]:
    """A point's tracks' values of MULTI_TARGET_COLUMNS, then of its targets' columns."""
    delays = x.confirmation_delays
    return [
        x.localisation_m2,
        x.missed_m2,
        x.false_m2,
        x.id_switches,
        x.runs_with_false_tracks,
        x.longest_false_run,
        float(np.median(delays)) if delays else math.nan,
        max(delays) if delays else math.nan,
        x.never_confirmed,
        *(v for pair in zip(x.rmse_m, x.bound_m2, strict=True) for v in pair),
    ]


def _cell(v: object) -> object:
    return repr(v) if isinstance(v, float) else v


def write_csv(summaries: Sequence[PointSummary], paths: Sequence[str], out: Path) -> Path:
    """One row per (point, method): the swept values (one column per path), then the metrics
    (module docstring: the tracks' columns only when a point has its tracks' figures)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    n_targets = max((len(s.tracking.rmse_m) for s in summaries if s.tracking), default=None)
    extra = [] if n_targets is None else [*MULTI_TARGET_COLUMNS, *target_columns(n_targets)]
    with out.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow([*paths, *SUMMARY_COLUMNS, *extra])
        for s in summaries:
            vals = dict(s.values)
            cells = [] if s.tracking is None else tracking_cells(s.tracking)
            w.writerow(
                [
                    *(fmt_value(vals[p]) for p in paths),
                    *(_cell(getattr(s, c)) for c in SUMMARY_COLUMNS),
                    *(_cell(v) for v in cells),
                    *[""] * (len(extra) - len(cells)),
                ]
            )
    return out


def write_rows_csv(rows: Sequence[TaskRow], out: Path) -> Path:
    """The per-run rows (one per task), sorted by point, method, run (`figures` left out)."""
    out.parent.mkdir(parents=True, exist_ok=True)
    names = [f.name for f in fields(TaskRow) if f.name != "figures"]
    with out.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(names)
        for r in sorted(rows, key=lambda r: (r.point, r.method, r.run)):
            w.writerow(
                [repr(v) if isinstance(v, float) else v for v in map(r.__getattribute__, names)]
            )
    return out


def _ci(mean: float, lo: float, hi: float) -> str:
    return "-" if math.isnan(mean) else f"{mean:.3g} ({lo:.3g}-{hi:.3g})"


def _g(v: float) -> str:
    return "-" if math.isnan(v) else f"{v:.3g}"


def sweep_table(summaries: Sequence[PointSummary], paths: Sequence[str], title: str) -> Table:
    """Rich table: swept values (headed by the path's last key), method, then the labelled
    track's RMSE with its 95 % CI and mean tr(PCRB) parts (if a point has one), GOSPA with its
    95 % CI, the share of a point's runs with a false track, confirmation delays and each
    target's RMSE / tr(PCRB_pos) (if a point has its tracks' figures), infeasible slots, median
    planning time; "-": not of this point's kind."""
    single = any(s.tracking is None for s in summaries)
    n_targets = max((len(s.tracking.rmse_m) for s in summaries if s.tracking), default=0)
    t = Table(title=title, caption=" / ".join(paths))
    for p in paths:
        t.add_column(p.rsplit(".", 1)[-1], justify="right")
    columns = ["method"]
    if single:
        columns += ["loc RMSE m (95% CI)", "vel RMSE m/s (95% CI)", "PCRB pos", "PCRB vel"]
    columns.append("GOSPA m (95% CI)")
    if n_targets:
        columns += ["false-track runs", "confirm delay med/max"]
        columns += [f"target {i} RMSE m / PCRB pos" for i in range(n_targets)]
    columns += ["infeas.", "plan ms"]
    for col in columns:
        t.add_column(col, justify="left" if col == "method" else "right")
    for s in summaries:
        vals = dict(s.values)
        cells = [s.method]
        if single:
            cells += [
                _ci(s.loc_rmse, s.loc_rmse_lo, s.loc_rmse_hi),
                _ci(s.vel_rmse, s.vel_rmse_lo, s.vel_rmse_hi),
                _g(s.pcrb_pos),
                _g(s.pcrb_vel),
            ]
        cells.append(_ci(s.gospa_m, s.gospa_m_lo, s.gospa_m_hi))
        if n_targets:
            x = s.tracking
            if x is None:
                cells += ["-"] * (2 + n_targets)
            else:
                delays = x.confirmation_delays
                cells += [
                    f"{100 * x.runs_with_false_tracks:.0f} %",
                    f"{np.median(delays):.0f} / {max(delays)}" if delays else "-",
                ]
                pairs = [f"{_g(r)} / {_g(b)}" for r, b in zip(x.rmse_m, x.bound_m2, strict=True)]
                cells += pairs + ["-"] * (n_targets - len(pairs))
        cells += [f"{s.infeasible_slots}/{s.slots}", f"{s.solve_median_ms:.1f}"]
        t.add_row(*(fmt_value(vals[p]) for p in paths), *cells)
    return t
