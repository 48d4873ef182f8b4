"""RMSE- and GOSPA-vs-parameter figures of a sweep: per swept path, the labelled track's location
and velocity RMSE if a point's runs had one, the mission-mean GOSPA if a point's runs had their
tracks' figures instead (no pyplot, no files).

`sweep_figures` returns them keyed by the file name the CLI writes them to
(`rmse_vs_<path with _ for .>.png`, `gospa_vs_<...>.png`, saved with
`save_png(fig, path, dpi=RMSE_PLOT_DPI)`).
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
GOSPA_PLOT_SIZE_IN: Final[tuple[float, float]] = (6.5, 4.2)
RMSE_PLOT_DPI: Final[int] = 110
"""The DPI of every sweep figure."""


def _numeric(values: Sequence[Value]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def rmse_plot_name(path: str) -> str:
    """The PNG file name of the RMSE-vs-`path` figure, e.g. rmse_vs_uavs_max_speed_mps.png."""
    return f"rmse_vs_{path.replace('.', '_')}.png"


def gospa_plot_name(path: str) -> str:
    """The PNG file name of the GOSPA-vs-`path` figure, e.g. gospa_vs_uavs_max_speed_mps.png."""
    return f"gospa_vs_{path.replace('.', '_')}.png"


def _draw_vs(
    summaries: Sequence[PointSummary],
    grid: GridSpec,
    path: str,
    panels: Sequence[tuple[Axes, str, str]],
) -> None:
    """Each panel (axes, PointSummary attribute with its _lo and _hi, y label): the attribute vs
    the swept value of `path`, one line per method (and per combination of the other swept
    values), with 95 % CI error bars; the first panel's legend."""
    values = dict(grid.axes)[path]
    numeric = _numeric(values)
    xs_of = {json.dumps(v): (float(cast(float, v)) if numeric else i) for i, v in enumerate(values)}
    lines: dict[str, list[PointSummary]] = {}
    for s in summaries:
        others = ", ".join(f"{p}={fmt_value(v)}" for p, v in s.values if p != path)
        lines.setdefault(s.method + (f" ({others})" if others else ""), []).append(s)
    for label, group in lines.items():
        group = sorted(group, key=lambda s: xs_of[json.dumps(dict(s.values)[path])])
        x = [xs_of[json.dumps(dict(s.values)[path])] for s in group]
        for ax, attr, _ in panels:
            y = np.array([getattr(s, attr) for s in group])
            lo = np.array([getattr(s, attr + "_lo") for s in group])
            hi = np.array([getattr(s, attr + "_hi") for s in group])
            err = np.nan_to_num(np.vstack([y - lo, hi - y]))
            ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=label)
    for ax, _, title in panels:
        ax.set_xlabel(path)
        ax.set_ylabel(title)
        ax.grid(True, alpha=0.3)
        if not numeric:
            ax.set_xticks(range(len(values)), [fmt_value(v) for v in values])
    panels[0][0].legend(fontsize=7)


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
    own = axes is None
    if axes is None:
        fig = new_figure(RMSE_PLOT_SIZE_IN, layout=None)
        ax_loc, ax_vel = fig.subplots(1, 2)
    else:
        ax_loc, ax_vel = axes
        fig = figure_of(ax_loc)
    _draw_vs(
        summaries,
        grid,
        path,
        [(ax_loc, "loc_rmse", "location RMSE [m]"), (ax_vel, "vel_rmse", "velocity RMSE [m/s]")],
    )
    if own:
        fig.suptitle(f"RMSE vs {path} (95 % t-interval over {grid.runs} runs)")
        fig.tight_layout()
    return fig


def plot_gospa_vs(
    summaries: Sequence[PointSummary],
    grid: GridSpec,
    path: str,
    ax: Axes | None = None,
) -> Figure:
    """Mission-mean GOSPA (m) vs the swept value of `path`, one line per method (and per
    combination of the other swept values), with 95 % CI error bars.

    Draws into `ax` if given, else into a new Figure of GOSPA_PLOT_SIZE_IN inches with a title;
    returns the Figure.
    """
    own = ax is None
    if ax is None:
        fig = new_figure(GOSPA_PLOT_SIZE_IN, layout=None)
        ax = fig.add_subplot()
    else:
        fig = figure_of(ax)
    _draw_vs(summaries, grid, path, [(ax, "gospa_m", "mission-mean GOSPA [m]")])
    if own:
        fig.suptitle(f"GOSPA vs {path} (95 % t-interval over {grid.runs} runs)")
        fig.tight_layout()
    return fig


def sweep_figures(summaries: Sequence[PointSummary], grid: GridSpec) -> dict[str, Figure]:
    """Per swept path, in grid order: `plot_rmse_vs` if a point had a labelled track (keyed by
    `rmse_plot_name(path)`), `plot_gospa_vs` if a point had its tracks' figures instead
    (`gospa_plot_name(path)`)."""
    single = [s for s in summaries if s.tracking is None]
    multi = [s for s in summaries if s.tracking is not None]
    out: dict[str, Figure] = {}
    for path in grid.paths:
        if single:
            out[rmse_plot_name(path)] = plot_rmse_vs(single, grid, path)
        if multi:
            out[gospa_plot_name(path)] = plot_gospa_vs(multi, grid, path)
    return out
