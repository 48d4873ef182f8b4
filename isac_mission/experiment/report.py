"""`simulate`'s report: Monte Carlo with a progress bar, the tables, summary.json and the plots.

Both comparison tables put each method against `proposed` (the reference) as a % change,
100 (method / proposed - 1) from bootstrap.change_pct: negative = lower (better) than `proposed`.
Each states it in its title; with one run the interval column's caption says why there is none.

Tables print whole when the output is not a terminal (a pipe, a log file, CI): `print_table`
renders them at least TABLE_WIDTH_NOT_TERMINAL columns wide (wider if a table needs it) instead
of rich's 80-column default, which cuts cells ("Prop…", "0.02…").
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import asdict
from pathlib import Path

from rich.console import Console
from rich.measure import Measurement
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from isac_mission.config import Scenario
from isac_mission.experiment.bootstrap import Interval, change_pct
from isac_mission.experiment.comparison import (
    BASELINE,
    CHANGES,
    NEEDS_TWO_RUNS,
    Change,
    change_convention,
    changes_against_reference,
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


def gospa_table(summaries: Sequence[MethodSummary], cutoff_m: float) -> Table:
    """One row per method: the mission-mean GOSPA and the target's mean position bound, the
    figures a scenario of several targets reports per target (experiment/multi_target_report.py)."""
    t = Table(title=f"GOSPA (c = {cutoff_m:g} m, p = 2) and the target's bound")
    for col in ("method", "GOSPA m", "tr(PCRB_pos) m²"):
        t.add_column(col, justify="right" if col != "method" else "left")
    for s in summaries:
        t.add_row(LABELS.get(s.method, s.method), f"{s.gospa_m:.4g}", f"{s.pcrb_pos:.4g}")
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


def runs_text(runs: int) -> str:
    """'1 run', '20 runs'."""
    return f"{runs} run" if runs == 1 else f"{runs} runs"


def interval_cell(iv: Interval | None) -> str:
    """'+18.6 % [16.6, 20.5]' (estimate and interval, %), or '-' when there is none."""
    if iv is None:
        return "-"
    return f"{iv.estimate:+.1f} % [{iv.low:+.1f}, {iv.high:+.1f}]"


def change_cell(c: Change) -> str:
    """'+18.6 % [+16.6, +20.5]' (% change and its interval), '+18.6 %' (no interval: the
    table's caption says why), or '-' (no value)."""
    if c.interval is not None:
        return interval_cell(c.interval)
    return "-" if c.estimate is None else f"{c.estimate:+.1f} %"


def missing_caption(changes: Iterable[Change], runs: int) -> str | None:
    """The caption that says why cells have no interval (or no value), None when all have one."""
    why = sorted({c.missing for c in changes if c.missing is not None})
    notes = [
        f"no interval: {w} ({runs_text(runs)} here)" if w == NEEDS_TWO_RUNS else f"'-': {w}"
        for w in why
    ]
    return "; ".join(notes) or None


def against_reference_table(
    changes: dict[str, dict[str, Change]], runs: int, level: float = 0.95
) -> Table:
    """Per method: % change of each figure against `proposed` with its paired interval."""
    ref = LABELS[BASELINE]
    t = Table(
        title=f"Each method against {ref}: {change_convention(ref)}; "
        f"paired bootstrap {level:.0%} interval over {runs_text(runs)}",
        caption=missing_caption((c for row in changes.values() for c in row.values()), runs),
    )
    t.add_column("method")
    for key in CHANGES:
        t.add_column(FIGURE_HEADS[key], justify="right")
    for method, row in changes.items():
        t.add_row(LABELS.get(method, method), *(change_cell(row[k]) for k in CHANGES))
    return t


def change_record(c: Change, level: float = 0.95) -> dict[str, float | str | None]:
    """summary.json's form of a Change: estimate, low, high (%, None without an interval),
    level, and `missing` (why there is no interval, else None)."""
    iv = c.interval
    return {
        "estimate": c.estimate,
        "low": None if iv is None else iv.low,
        "high": None if iv is None else iv.high,
        "level": level if iv is None else iv.level,
        "missing": c.missing,
    }


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


BENCHMARKS = ("sd", "aba", "crb")
"""The benchmarks the paper reports reductions against (PAPER_REDUCTIONS)."""


def paper_change_pct(reduction: float) -> float:
    """The paper's % reduction of the proposed method against a benchmark (proposed =
    (1 - reduction / 100) x benchmark) as the benchmark's % change against the proposed method."""
    return float(change_pct(1.0, 1.0 - reduction / 100.0))


def reduction_rows(by_method: dict[str, MethodSummary]) -> list[dict[str, float | str | None]]:
    """The proposed method's % reductions against each benchmark, beside the paper's
    (summary.json's `reductions`: positive = the proposed method lower; the printed table is
    `benchmark_rows`)."""
    p = by_method["proposed"]
    rows: list[dict[str, float | str | None]] = []
    for bench in BENCHMARKS:
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


def benchmark_rows(by_method: dict[str, MethodSummary]) -> list[dict[str, float | str]]:
    """Each benchmark's % change against the proposed method (change_pct: negative = the
    benchmark lower), mean tr(PCRB) and RMSEs over slots 1..N, beside the paper's reductions
    restated the same way (paper_change_pct); summary.json's `benchmarks_against_proposed`."""
    p = by_method[BASELINE]
    rows: list[dict[str, float | str]] = []
    for bench in BENCHMARKS:
        if bench not in by_method:
            continue
        b = by_method[bench]
        loc_paper, vel_paper = PAPER_REDUCTIONS[bench]
        rows.append(
            {
                "benchmark": bench,
                "pcrb_change_pct": float(change_pct(b.pcrb_total, p.pcrb_total)),
                "loc_change_pct": float(change_pct(b.loc_rmse, p.loc_rmse)),
                "loc_paper_change_pct": paper_change_pct(loc_paper),
                "vel_change_pct": float(change_pct(b.vel_rmse, p.vel_rmse)),
                "vel_paper_change_pct": paper_change_pct(vel_paper),
            }
        )
    return rows


def benchmark_table(rows: list[dict[str, float | str]]) -> Table:
    """Each benchmark against the proposed method beside the paper, in the sign convention of
    every comparison table (change_convention); the caption gives the paper's printed figures."""
    ref = LABELS[BASELINE]
    printed = ", ".join(
        f"{LABELS[str(r['benchmark'])]} {PAPER_REDUCTIONS[str(r['benchmark'])][0]:.1f} % / "
        f"{PAPER_REDUCTIONS[str(r['benchmark'])][1]:.1f} %"
        for r in rows
    )
    t = Table(
        title=f"Each benchmark against {ref}, beside the paper: {change_convention(ref)}",
        caption=f"paper loc / paper vel: the paper's reductions of {ref}'s RMSEs against each "
        f"benchmark ({printed}) as the benchmark's change against {ref}",
    )
    for col in ("method", "tr(PCRB)", "loc RMSE", "paper loc", "vel RMSE", "paper vel"):
        t.add_column(col, justify="right" if col != "method" else "left")
    for r in rows:
        t.add_row(
            LABELS[str(r["benchmark"])],
            *(
                f"{float(r[k]):+.1f} %"
                for k in (
                    "pcrb_change_pct",
                    "loc_change_pct",
                    "loc_paper_change_pct",
                    "vel_change_pct",
                    "vel_paper_change_pct",
                )
            ),
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
    cutoff_m = s.multi_tracker.gospa_cutoff_m
    summaries: dict[str, MethodSummary] = {m: summarize(results[m], cutoff_m) for m in methods}
    print_table(
        console, summary_table(list(summaries.values()), f"{s.mission_id}: {runs_text(runs)}")
    )
    print_table(console, gospa_table(list(summaries.values()), cutoff_m))
    rows = reduction_rows(summaries) if BASELINE in summaries else []
    bench_rows = benchmark_rows(summaries) if BASELINE in summaries else []
    if bench_rows:
        print_table(console, benchmark_table(bench_rows))
    figures: dict[str, dict[str, FloatArray]] = {m: run_figures(results[m]) for m in methods}
    print_table(
        console,
        figures_table(
            list(summaries.values()), f"{s.mission_id}: tr(PCRB) and errors, {runs_text(runs)}"
        ),
    )
    changes = changes_against_reference(figures, seed=seed)
    if changes:
        print_table(console, against_reference_table(changes, runs))
    against = reductions_against_baseline(figures, seed=seed)
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = {
        "config": s.trace_config(),
        "runs": runs,
        "seed": seed,
        "methods": {m: asdict(v) for m, v in summaries.items()},
        "reductions": rows,
        "benchmarks_against_proposed": bench_rows,
        "against_proposed": {
            m: {k: None if iv is None else asdict(iv) for k, iv in row.items()}
            for m, row in against.items()
        },
        "change_against_proposed": {
            m: {k: change_record(c) for k, c in row.items()} for m, row in changes.items()
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
