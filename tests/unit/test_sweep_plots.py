"""Sweep plots: one RMSE-vs-parameter Figure per swept path, named as the CLI writes it; drawn
into the caller's axes when given them."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import cast

from matplotlib.figure import Figure

from isac_mission.config import Scenario
from isac_mission.experiment.plots import save_png
from isac_mission.experiment.sweep.grid import GridPoint, GridSpec, parse_grid
from isac_mission.experiment.sweep.plots import (
    RMSE_PLOT_DPI,
    RMSE_PLOT_SIZE_IN,
    plot_rmse_vs,
    rmse_plot_name,
    sweep_figures,
)
from isac_mission.experiment.sweep.runs import TaskRow
from isac_mission.experiment.sweep.summary import PointSummary, aggregate


def _summaries() -> tuple[list[PointSummary], GridSpec]:
    grid = parse_grid(
        {"uavs.max_speed_mps": [15, 25], "methods": ["proposed", "sd"], "runs": 2, "slots": 3}
    )
    points = [
        GridPoint(
            index=i, values=(("uavs.max_speed_mps", v),), scenario=cast(Scenario, None), key=str(i)
        )
        for i, v in enumerate([15, 25])
    ]
    rows = [
        TaskRow(p, m, r, r, 1.0 + p + r, 0.01 * (1 + r), 2.0, 0.02, 5.0, 0, 3)
        for p in range(2)
        for m in ("proposed", "sd")
        for r in range(2)
    ]
    return aggregate(rows, points), grid


def test_one_figure_per_swept_path_named_as_the_cli_writes_it(tmp_path: Path) -> None:
    summaries, grid = _summaries()
    figures = sweep_figures(summaries, grid)
    assert list(figures) == ["rmse_vs_uavs_max_speed_mps.png"]
    assert rmse_plot_name("radio.rate_min_bps") == "rmse_vs_radio_rate_min_bps.png"
    (fig,) = figures.values()
    assert isinstance(fig, Figure)
    ax_loc, ax_vel = fig.axes
    assert len(ax_loc.containers) == 2 and len(ax_vel.containers) == 2  # one per method
    out = save_png(fig, tmp_path / "rmse.png", dpi=RMSE_PLOT_DPI)
    width, height = struct.unpack(">II", out.read_bytes()[16:24])
    assert (width, height) == (
        round(RMSE_PLOT_SIZE_IN[0] * RMSE_PLOT_DPI),
        round(RMSE_PLOT_SIZE_IN[1] * RMSE_PLOT_DPI),
    )


def test_rmse_plot_draws_into_the_callers_axes() -> None:
    summaries, grid = _summaries()
    fig = Figure()
    ax_loc, ax_vel = fig.subplots(1, 2)
    assert plot_rmse_vs(summaries, grid, "uavs.max_speed_mps", axes=(ax_loc, ax_vel)) is fig
    assert len(fig.axes) == 2
    assert ax_loc.get_xlabel() == "uavs.max_speed_mps"
    assert ax_vel.get_ylabel() == "velocity RMSE [m/s]"
    assert len(ax_loc.containers) == 2
