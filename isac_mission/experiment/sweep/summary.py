"""Aggregates of a sweep and their outputs: per-point summaries, the two CSV files, the table.

Aggregates per (point, method): location / velocity RMSE over runs with a 95 % confidence
interval (Student-t interval of the mean per-run MSE over runs, mapped through sqrt), mean
tr(PCRB) parts, solve time, infeasible slots.
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
from isac_mission.planning.registry import METHODS


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
                    *(fmt_value(vals[p]) for p in paths),
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
            *(fmt_value(vals[p]) for p in paths),
            s.method,
            f"{s.loc_rmse:.3g} ({s.loc_rmse_lo:.3g}-{s.loc_rmse_hi:.3g})",
            f"{s.vel_rmse:.3g} ({s.vel_rmse_lo:.3g}-{s.vel_rmse_hi:.3g})",
            f"{s.pcrb_pos:.3g}",
            f"{s.pcrb_vel:.3g}",
            f"{s.infeasible_slots}/{s.slots}",
            f"{s.solve_median_ms:.1f}",
        )
    return t
