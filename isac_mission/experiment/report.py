"""`simulate`'s report: Monte Carlo with a progress bar, the tables, summary.json and the plots.

Tables print whole when the output is not a terminal (a pipe, a log file, CI): `print_table`
renders them at least TABLE_WIDTH_NOT_TERMINAL columns wide (wider if a table needs it) instead
of rich's 80-column default, which cuts cells ("Prop…", "0.02…").
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

from rich.console import Console
from rich.measure import Measurement
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from isac_mission.config import Scenario
from isac_mission.experiment.bootstrap import Interval
from isac_mission.experiment.comparison import (
    BASELINE,
    FIGURES,
    reductions_against_baseline,
    run_figures,
)
from isac_mission.experiment.montecarlo import (
    PAPER_REDUCTIONS,
    MethodSummary,
    reduction_pct,
    run_monte_carlo,
    summarize,
    trace_path,
)
from isac_mission.planning.registry import LABELS
from isac_mission.planning.slot import Method
from isac_mission.types import FloatArray

TABLE_WIDTH_NOT_TERMINAL = 160
"""Columns a table is rendered in when the console is not a terminal (at least)."""


FIGURE_HEADS = {
    "pcrb": "tr(PCRB)",
    "pcrb_from11": "slots 11..N",
    "pcrb_late": "2nd half",
    "loc_mse": "RMSE loc (2..N)",
    "vel_mse": "RMSE vel (2..N)",
}
"""Column heads of the figures of experiment/comparison.py (tr(PCRB) = whole trace, m² + (m/s)²)."""


def summary_table(summaries: Sequence[MethodSummary], title: str) -> Table:
    """One row per method: bound, errors, efficiency, infeasible slots, slots whose method's
    answer was not flown (SolveReport.fallback; summary.json has them by kind), planning time."""
    t = Table(title=title)
    for col in (
        "method",
        "PCRB pos m²",
        "PCRB vel (m/s)²",
        "PCRB pos 2nd half",
        "RMSE loc m",
        "RMSE vel m/s",
        "MSE/PCRB",
        "infeas.",
        "fallbacks",
        "plan ms med",
        "p95",
    ):
        t.add_column(col, justify="right" if col != "method" else "left")
    for s in summaries:
        t.add_row(
            LABELS.get(s.method, s.method),
            f"{s.pcrb_pos:.4g}",
            f"{s.pcrb_vel:.4g}",
            f"{s.pcrb_pos_late:.4g}",
            f"{s.loc_rmse:.4g}",
            f"{s.vel_rmse:.4g}",
            f"{s.efficiency:.3f}",
            f"{s.infeasible_slots}/{s.slots}",
            f"{sum(s.fallbacks.values())}/{s.slots}",
            f"{s.solve_median_ms:.1f}",
            f"{s.solve_p95_ms:.1f}",
        )
    return t


def figures_table(summaries: Sequence[MethodSummary], title: str) -> Table:
    """One row per method: whole tr(PCRB) (mission mean, slots 11..N, second half), location and
    velocity RMSE over slots 2..N pooled over runs, MSE / tr(PCRB_pos), plan time."""
    t = Table(title=title)
    heads = ["method", *FIGURE_HEADS.values(), "MSE/PCRB", "plan ms med", "p95"]
    for col in heads:
        t.add_column(col, justify="right" if col != "method" else "left")
    for s in summaries:
        t.add_row(
            LABELS.get(s.method, s.method),
            f"{s.pcrb_total:.4g}",
            f"{s.pcrb_from11:.4g}",
            f"{s.pcrb_late:.4g}",
            f"{s.loc_rmse_from2:.4g}",
            f"{s.vel_rmse_from2:.4g}",
            f"{s.efficiency:.3f}",
            f"{s.solve_median_ms:.1f}",
            f"{s.solve_p95_ms:.1f}",
        )
    return t


def interval_cell(iv: Interval | None) -> str:
    """'+18.6 % [16.6, 20.5]' (estimate and interval, %), or '-' when there is none."""
    if iv is None:
        return "-"
    return f"{iv.estimate:+.1f} % [{iv.low:+.1f}, {iv.high:+.1f}]"


def against_baseline_table(
    reductions: dict[str, dict[str, Interval | None]], runs: int, level: float = 0.95
) -> Table:
    """Per method: % reduction of each figure against `proposed` with its paired interval."""
    t = Table(
        title=f"Against {LABELS[BASELINE]}: % reduction (positive = lower than {LABELS[BASELINE]}), "
        f"paired bootstrap {level:.0%} interval over {runs} runs"
    )
    t.add_column("method")
    for key in FIGURES:
        t.add_column(FIGURE_HEADS[key], justify="right")
    for method, row in reductions.items():
        t.add_row(LABELS.get(method, method), *(interval_cell(row[k]) for k in FIGURES))
    return t


def print_table(console: Console, table: Table) -> None:
    """Print `table` on `console` with no cell cut: on a terminal at the terminal's width (as
    rich does); elsewhere at max(TABLE_WIDTH_NOT_TERMINAL, the table's natural width) columns."""
    if console.is_terminal:
        console.print(table)
        return
    natural = Measurement.get(console, console.options.update_width(10_000), table).maximum
    wide = Console(
        file=console.file,
        width=max(TABLE_WIDTH_NOT_TERMINAL, natural),
        force_terminal=False,
        no_color=console.no_color,
    )
    wide.print(table)


def reduction_rows(by_method: dict[str, MethodSummary]) -> list[dict[str, float | str | None]]:
    """The proposed method's % reductions against each benchmark, beside the paper's."""
    p = by_method["proposed"]
    rows: list[dict[str, float | str | None]] = []
    for bench in ("sd", "aba", "crb"):
        if bench not in by_method:
            continue
        b = by_method[bench]
        paper = PAPER_REDUCTIONS[bench]
        rows.append(
            {
                "benchmark": bench,
                "pcrb_pct": reduction_pct(p.pcrb_total, b.pcrb_total),
                "loc_pct": reduction_pct(p.loc_rmse, b.loc_rmse),
                "loc_paper_pct": paper[0],
                "vel_pct": reduction_pct(p.vel_rmse, b.vel_rmse),
                "vel_paper_pct": paper[1],
            }
        )
    return rows


def reduction_table(rows: list[dict[str, float | str | None]]) -> Table:
    t = Table(title="Proposed vs benchmarks: % reduction (positive = proposed is better)")
    for col in ("vs", "tr(PCRB)", "loc RMSE", "paper loc", "vel RMSE", "paper vel"):
        t.add_column(col, justify="right" if col != "vs" else "left")
    for r in rows:
        t.add_row(
            LABELS[str(r["benchmark"])],
            f"{r['pcrb_pct']:+.1f} %",
            f"{r['loc_pct']:+.1f} %",
            f"{r['loc_paper_pct']:.1f} %",
            f"{r['vel_pct']:+.1f} %",
            f"{r['vel_paper_pct']:.1f} %",
        )
    return t


def mission_progress(console: Console) -> Progress:
    """The progress bar of Monte Carlo commands (missions done / total, elapsed time)."""
    return Progress(
        TextColumn("[progress.description]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
    )


def simulate_report(
    s: Scenario,
    methods: Sequence[Method],
    *,
    runs: int,
    seed: int,
    out_dir: Path,
    workers: int,
    plots: bool,
    console: Console,
) -> dict[str, MethodSummary]:
    """Run the Monte Carlo, print the tables, write traces, summary.json and the plots."""
    trace_dir = out_dir / "traces"
    console.print(
        f"[bold]{s.mission_id}[/]: M={s.M} UAVs, K={s.K} BSs, N={s.N} slots, "
        f"{runs} runs x {len(methods)} methods, seeds {seed}..{seed + runs - 1}, "
        f"sensing model {s.sensing_model}"
    )
    with mission_progress(console) as bar:
        task = bar.add_task("missions", total=runs * len(methods))
        results = run_monte_carlo(
            s,
            methods,
            runs,
            seed,
            trace_dir=trace_dir,
            progress=lambda m, r: bar.advance(task),
            workers=workers,
        )
    summaries: dict[str, MethodSummary] = {m: summarize(results[m]) for m in methods}
    print_table(console, summary_table(list(summaries.values()), f"{s.mission_id}: {runs} runs"))
    rows = reduction_rows(summaries) if "proposed" in summaries else []
    if rows:
        print_table(console, reduction_table(rows))
    figures: dict[str, dict[str, FloatArray]] = {m: run_figures(results[m]) for m in methods}
    print_table(
        console,
        figures_table(
            list(summaries.values()), f"{s.mission_id}: tr(PCRB) and errors, {runs} runs"
        ),
    )
    against = reductions_against_baseline(figures, seed=seed)
    if against:
        print_table(console, against_baseline_table(against, runs))
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = {
        "config": s.trace_config(),
        "runs": runs,
        "seed": seed,
        "methods": {m: asdict(v) for m, v in summaries.items()},
        "reductions": rows,
        "against_proposed": {
            m: {k: None if iv is None else asdict(iv) for k, iv in row.items()}
            for m, row in against.items()
        },
        "per_run": {m: {k: v.tolist() for k, v in f.items()} for m, f in figures.items()},
    }
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    if plots:
        from isac_mission.experiment.plots import (
            plot_bandwidth,
            plot_performance,
            plot_trajectories,
            save_png,
        )
        from isac_mission.records import read_trace

        first = "proposed" if "proposed" in methods else methods[0]
        run0 = read_trace(trace_path(trace_dir, first, 0))
        performance = plot_performance(
            {
                LABELS.get(m, m): [read_trace(trace_path(trace_dir, m, r)) for r in range(runs)]
                for m in methods
            }
        )
        written = [
            save_png(plot_trajectories(run0), out_dir / "fig2a_trajectories.png"),
            save_png(plot_bandwidth(run0), out_dir / "fig2b_bandwidth.png"),
            save_png(performance, out_dir / "fig3_performance.png"),
        ]
        console.print("plots: " + ", ".join(str(p) for p in written))
    console.print(f"traces: {trace_dir}/  summary: {out_dir / 'summary.json'}")
    return summaries
