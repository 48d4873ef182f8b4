"""`isac-mission sweep`: Monte Carlo over a parameter grid (serial, or on Dask)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from isac_mission.cli.app import ConfigArg, app, console, err_console
from isac_mission.errors import ConfigError, MissingDependencyError
from isac_mission.quiet import quiet_highs_banner


@app.command()
def sweep(
    config: ConfigArg,
    grid: Annotated[
        Path,
        typer.Option(
            help="Grid YAML: dotted config paths -> lists of values (+ methods, "
            "runs, seed, slots); see config/grids/example.yaml."
        ),
    ],
    out: Annotated[
        Path | None, typer.Option(help="Output folder (sweep.csv, runs.csv, plots).")
    ] = None,
    workers: Annotated[
        int, typer.Option(min=0, help="Local Dask worker processes (0: serial, no Dask).")
    ] = 2,
    serial: Annotated[bool, typer.Option(help="Run in this process without Dask.")] = False,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Existing Dask scheduler, e.g. tcp://HOST:8786 (default: a local "
            "cluster on 127.0.0.1)."
        ),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(min=0, help="Base seed (default: the grid's, else the config's)."),
    ] = None,
    plots: Annotated[bool, typer.Option(help="Write RMSE- (or GOSPA-) vs-parameter PNGs.")] = True,
    live_settings: Annotated[
        bool,
        typer.Option(
            "--live-settings",
            help="Plan every point with what `run` and `serve` plan with (docs/model.md, "
            "'Live service').",
        ),
    ] = False,
) -> None:
    """Monte Carlo over a parameter grid, on Dask (grid point x method x run, seed = seed + run)."""
    from isac_mission.experiment.report import mission_progress, print_table
    from isac_mission.experiment.sweep import runs as sw
    from isac_mission.experiment.sweep.summary import (
        aggregate,
        sweep_table,
        write_csv,
        write_rows_csv,
    )

    try:
        from isac_mission.config.live_settings import LIVE_SETTINGS

        plan = sw.plan_sweep(config, grid, seed, LIVE_SETTINGS if live_settings else None)
    except ConfigError as err:
        from rich.markup import escape

        err_console.print(f"[bold red]invalid sweep:[/] {escape(str(err))}", highlight=False)
        raise typer.Exit(2) from None
    use_dask = not serial and (workers > 0 or scheduler is not None)
    if use_dask:
        from rich.markup import escape

        from isac_mission.experiment.sweep.cluster import require_dask

        try:
            require_dask()
        except MissingDependencyError as err:
            err_console.print(f"[bold red]sweep[/]: {escape(str(err))}", highlight=False)
            raise typer.Exit(2) from None
    where = (
        f"scheduler {scheduler}"
        if scheduler and use_dask
        else (f"local cluster of {workers} workers on 127.0.0.1" if use_dask else "serial")
    )
    g = plan.grid
    console.print(
        f"[bold]{plan.mission_id}[/]: {len(plan.points)} grid points x {len(g.methods)} methods x "
        f"{g.runs} runs = {len(plan.tasks)} missions, seeds {plan.seed}..{plan.seed + g.runs - 1}, "
        f"{where}",
        highlight=False,
    )
    quiet_highs_banner()
    with mission_progress(console) as bar:
        task = bar.add_task("missions", total=len(plan.tasks))

        def done(_row: sw.TaskRow) -> None:
            bar.advance(task)

        if use_dask:
            from isac_mission.experiment.sweep.cluster import dask_client, run_dask

            with dask_client(scheduler, workers) as client:
                rows = run_dask(client, plan.tasks, done)
        else:
            rows = sw.run_serial(plan.tasks, done)
    summaries = aggregate(rows, plan.points)
    print_table(
        console,
        sweep_table(
            summaries, g.paths, f"{plan.mission_id}: {g.runs} runs per point (95% t-intervals)"
        ),
    )
    out_dir = out if out is not None else Path("out") / f"sweep-{plan.mission_id}"
    csv_path = write_csv(summaries, g.paths, out_dir / "sweep.csv")
    write_rows_csv(rows, out_dir / "runs.csv")
    console.print(f"results: {csv_path}  per-run rows: {out_dir / 'runs.csv'}")
    if plots:
        from isac_mission.experiment.plots import save_png
        from isac_mission.experiment.sweep.plots import RMSE_PLOT_DPI, sweep_figures

        written = [
            save_png(fig, out_dir / name, dpi=RMSE_PLOT_DPI)
            for name, fig in sweep_figures(summaries, g).items()
        ]
        console.print("plots: " + ", ".join(str(p) for p in written))
