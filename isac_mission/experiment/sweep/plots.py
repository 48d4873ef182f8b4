"""RMSE-vs-parameter figures of a sweep: one Figure per swept path (no pyplot, no files).

`sweep_figures` returns them keyed by the file name the CLI writes them to
(`rmse_vs_<path with _ for .>.png`, saved with `save_png(fig, path, dpi=RMSE_PLOT_DPI)`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Final, cast

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from isac_mission.experiment.plots import figure_of, new_figure
from isac_mission.experiment.sweep.grid import GridSpec, Value, fmt_value
from isac_mission.experiment.sweep.summary import PointSummary

RMSE_PLOT_SIZE_IN: Final[tuple[float, float]] = (11.0, 4.2)
RMSE_PLOT_DPI: Final[int] = 110


def _numeric(values: Sequence[Value]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def rmse_plot_name(path: str) -> str:
    """The PNG file name of the RMSE-vs-`path` figure, e.g. rmse_vs_uavs_max_speed_mps.png."""
    return f"rmse_vs_{path.replace('.', '_')}.png"


def plot_rmse_vs(
    summaries: Sequence[PointSummary],
    grid: GridSpec,
    path: str,
    axes: tuple[Axes, Axes] | None = None,
) -> Figure:
    """Location RMSE (m) and velocity RMSE (m/s) vs the swept value of `path`, one line per
    method (and per combination of the other swept values), with 95 % CI error bars.

    Draws into `axes` = (location, velocity) if given, else into a new Figure of
    RMSE_PLOT_SIZE_IN inches with a title; returns the Figure.
    """
    values = dict(grid.axes)[path]
    numeric = _numeric(values)
    xs_of = {json.dumps(v): (float(cast(float, v)) if numeric else i) for i, v in enumerate(values)}
    lines: dict[str, list[PointSummary]] = {}
    for s in summaries:
        others = ", ".join(f"{p}={fmt_value(v)}" for p, v in s.values if p != path)
        lines.setdefault(s.method + (f" ({others})" if others else ""), []).append(s)
    own = axes is None
    if axes is None:
        fig = new_figure(RMSE_PLOT_SIZE_IN, layout=None)
        ax_loc, ax_vel = fig.subplots(1, 2)
    else:
        ax_loc, ax_vel = axes
        fig = figure_of(ax_loc)
    for label, group in lines.items():
        group = sorted(group, key=lambda s: xs_of[json.dumps(dict(s.values)[path])])
        x = [xs_of[json.dumps(dict(s.values)[path])] for s in group]
        for ax, attr in ((ax_loc, "loc_rmse"), (ax_vel, "vel_rmse")):
            y = np.array([getattr(s, attr) for s in group])
            lo = np.array([getattr(s, attr + "_lo") for s in group])
            hi = np.array([getattr(s, attr + "_hi") for s in group])
            err = np.nan_to_num(np.vstack([y - lo, hi - y]))
            ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=label)
    for ax, title in ((ax_loc, "location RMSE [m]"), (ax_vel, "velocity RMSE [m/s]")):
        ax.set_xlabel(path)
        ax.set_ylabel(title)
        ax.grid(True, alpha=0.3)
        if not numeric:
            ax.set_xticks(range(len(values)), [fmt_value(v) for v in values])
    ax_loc.legend(fontsize=7)
    if own:
        fig.suptitle(f"RMSE vs {path} (95 % t-interval over {grid.runs} runs)")
        fig.tight_layout()
    return fig


def sweep_figures(summaries: Sequence[PointSummary], grid: GridSpec) -> dict[str, Figure]:
    """`plot_rmse_vs` of every swept path, in grid order, keyed by `rmse_plot_name(path)`."""
    return {rmse_plot_name(path): plot_rmse_vs(summaries, grid, path) for path in grid.paths}
