"""`simulate`'s report, for any number of targets: Monte Carlo with a progress bar, the tables,
summary.json and the plots.

What is reported follows from what the runs measured (experiment/runs.py): runs with a labelled
track report that target's bound and errors (the summary, GOSPA, paper-benchmark, figures and
interval tables; summary.json's per-method `MethodSummary`, reductions, changes and per-run
figures; the Fig. 2 / Fig. 3 plots); runs whose tracks were found from unlabelled reports report
the tracks (GOSPA and its parts, ID switches, false tracks, confirmation delays, each target's
error against its track's bound, each method's GOSPA against the first method's; summary.json's
`TrackingSummary` per method and `against_baseline`; each method's tracks picture).

The labelled target's comparison tables put each method against `proposed` (the reference) as a % change,
100 (method / proposed - 1) from bootstrap.change_pct: negative = lower (better) than `proposed`.
Each states it in its title; with one run the interval column's caption says why there is none.

Tables print whole when the output is not a terminal (a pipe, a log file, CI): `print_table`
renders them at least TABLE_WIDTH_NOT_TERMINAL columns wide (wider if a table needs it) instead
of rich's 80-column default, which cuts cells ("Prop…", "0.02…").
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.measure import Measurement
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from isac_mission.config import Scenario
from isac_mission.experiment.bootstrap import (
    Interval,
    change_of_means,
    change_pct,
    paired_bootstrap,
    reduction_of_means,
)
from isac_mission.experiment.closed_loop import RunResult
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
    MissionRun,
    reduction_pct,
    run_monte_carlo,
    summarize,
    trace_path,
)
from isac_mission.experiment.track_metrics import TrackingSummary, summarize_tracking
from isac_mission.planning.registry import LABELS
from isac_mission.planning.slot import Method
from isac_mission.records.jsonlines import to_jsonable
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
    figures runs of unlabelled tracks report per target (`tracking_table`, `target_table`)."""
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


def tracking_table(summaries: Mapping[str, TrackingSummary], title: str) -> Table:
    """Per method: GOSPA and its parts, ID switches, false tracks, confirmation delays."""
    table = Table(title=title)
    for col in (
        "method",
        "GOSPA (m)",
        "loc. / missed / false (m^2)",
        "ID switches / run",
        "runs w/ false track",
        "longest false (slots)",
        "confirm delay median / max",
        "never confirmed",
    ):
        table.add_column(col, justify="right")
    for m, x in summaries.items():
        delays = x.confirmation_delays
        table.add_row(
            LABELS.get(m, m),
            f"{x.gospa_m:.3f}",
            f"{x.localisation_m2:.2f} / {x.missed_m2:.2f} / {x.false_m2:.2f}",
            f"{x.id_switches:.2f}",
            f"{100 * x.runs_with_false_tracks:.0f} %",
            str(x.longest_false_run),
            f"{np.median(delays):.0f} / {max(delays)}" if delays else "-",
            str(x.never_confirmed),
        )
    return table


def target_table(s: Scenario, summaries: Mapping[str, TrackingSummary]) -> Table:
    """Per method and target: location RMSE, mean tr(PCRB_pos), MSE / tr(PCRB_pos) over every
    slot a confirmed track followed it, and settled (without each run's first 10 of them)."""
    table = Table(
        title="each target, over the slots a confirmed track followed it "
        "(ratio = MSE / tr(PCRB_pos); settled: from its 11th such slot)"
    )
    table.add_column("method")
    for t in s.targets:
        table.add_column(
            f"{t.name}: RMSE (m) / tr(PCRB_pos) (m^2) / ratio / settled", justify="right"
        )
    for m, x in summaries.items():
        cells = [
            f"{r:.3f} / {b:.3f} / {e:.2f} / {e_s:.2f}"
            for r, b, e, e_s in zip(
                x.rmse_m, x.bound_m2, x.efficiency, x.settled_efficiency, strict=True
            )
        ]
        table.add_row(LABELS.get(m, m), *cells)
    return table


def gospa_against_reference(
    by_method: Mapping[str, Sequence[MissionRun]], reference: str, runs: int, seed: int
) -> tuple[Table, dict[str, Any]]:
    """Each method's mission-mean GOSPA against `reference`'s as a % change (change_of_means:
    negative = lower, better), paired bootstrap 95 % interval over runs (none with one run: the
    caption says so), and plan time median (ms). Returns the table and summary.json's
    `against_baseline` rows: `gospa_change_pct` [estimate, low, high] (low, high None with one
    run) and `gospa_reduction_pct` (the reduction, the opposite sign; None with one run)."""
    ref = LABELS.get(reference, reference)
    base = np.array([r.tracking.gospa_m.mean() for r in by_method[reference]])
    changes: dict[str, Change] = {}
    rows: dict[str, Any] = {}
    for m, method_runs in by_method.items():
        g = np.array([r.tracking.gospa_m.mean() for r in method_runs])
        reduction: list[float] | None = None
        if runs >= 2:
            iv = paired_bootstrap(base, g, change_of_means, seed=seed)
            c = Change(iv.estimate, iv)
            red = paired_bootstrap(base, g, reduction_of_means, seed=seed)
            reduction = [red.estimate, red.low, red.high]
        else:
            c = Change(float(change_of_means(base, g)), None, NEEDS_TWO_RUNS)
        changes[m] = c
        solve_s = np.concatenate([r.solve_s for r in method_runs])
        rows[m] = {
            "gospa_reduction_pct": reduction,
            "gospa_change_pct": [
                c.estimate,
                None if c.interval is None else c.interval.low,
                None if c.interval is None else c.interval.high,
            ],
            "plan_time_median_ms": 1e3 * float(np.median(solve_s)),
        }
    others = [c for m, c in changes.items() if m != reference]
    table = Table(
        title=f"GOSPA of each method against {ref}: {change_convention(ref)}; "
        f"paired bootstrap 95% interval over {runs_text(runs)}",
        caption=missing_caption(others, runs),
    )
    table.add_column("method")
    table.add_column("GOSPA change", justify="right")
    table.add_column("plan time median (ms)", justify="right")
    for m, c in changes.items():
        table.add_row(
            LABELS.get(m, m),
            "(reference)" if m == reference else change_cell(c),
            f"{rows[m]['plan_time_median_ms']:.1f}",
        )
    return table, rows


def labelled_runs(
    by_method: Mapping[str, Sequence[MissionRun]],
) -> dict[str, list[RunResult]] | None:
    """Every run's labelled track (runs.MissionRun.labelled), None when a run had none."""
    out: dict[str, list[RunResult]] = {}
    for m, method_runs in by_method.items():
        arrays = [r.labelled for r in method_runs]
        if any(a is None for a in arrays):
            return None
        out[m] = [a for a in arrays if a is not None]
    return out


def labelled_report(
    s: Scenario,
    results: Mapping[str, Sequence[RunResult]],
    runs: int,
    seed: int,
    console: Console,
) -> dict[str, Any]:
    """The labelled target's tables (module doc) printed; its summary.json returned."""
    cutoff_m = s.multi_tracker.gospa_cutoff_m
    summaries: dict[str, MethodSummary] = {m: summarize(r, cutoff_m) for m, r in results.items()}
    print_table(
        console, summary_table(list(summaries.values()), f"{s.mission_id}: {runs_text(runs)}")
    )
    print_table(console, gospa_table(list(summaries.values()), cutoff_m))
    rows = reduction_rows(summaries) if BASELINE in summaries else []
    bench_rows = benchmark_rows(summaries) if BASELINE in summaries else []
    if bench_rows:
        print_table(console, benchmark_table(bench_rows))
    figures: dict[str, dict[str, FloatArray]] = {m: run_figures(r) for m, r in results.items()}
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
    return {
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


def tracks_report(
    s: Scenario,
    by_method: Mapping[str, Sequence[MissionRun]],
    runs: int,
    seed: int,
    console: Console,
) -> dict[str, Any]:
    """The tracks' tables (module doc) printed, each method against the first; their
    summary.json returned."""
    summaries = {m: summarize_tracking([r.tracking for r in rs]) for m, rs in by_method.items()}
    n_targets = len(next(iter(by_method.values()))[0].tracking.targets)
    title = (
        f"{s.mission_id}: {runs_text(runs)}, {n_targets} targets, seeds {seed}..{seed + runs - 1}"
    )
    print_table(console, tracking_table(summaries, title))
    print_table(console, target_table(s, summaries))
    against, rows = gospa_against_reference(by_method, next(iter(by_method)), runs, seed)
    print_table(console, against)
    summary: dict[str, Any] = to_jsonable(
        {
            "scenario": s.mission_id,
            "runs": runs,
            "seed": seed,
            "methods": {m: to_jsonable(vars(x)) for m, x in summaries.items()},
            "against_baseline": rows,
        }
    )
    return summary


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
) -> dict[str, Any]:
    """Run the Monte Carlo, print the tables, write traces, summary.json and the plots (module
    doc); returns the summary (summary.json's content)."""
    trace_dir = out_dir / "traces"
    console.print(
        f"[bold]{s.mission_id}[/]: M={s.M} UAVs, K={s.K} BSs, N={s.N} slots, "
        f"{runs} runs x {len(methods)} methods, seeds {seed}..{seed + runs - 1}, "
        f"sensing model {s.sensing_model}"
    )
    with mission_progress(console) as bar:
        task = bar.add_task("missions", total=runs * len(methods))
        by_method = run_monte_carlo(
            s,
            methods,
            runs,
            seed,
            trace_dir=trace_dir,
            progress=lambda m, r: bar.advance(task),
            workers=workers,
        )
    labelled = labelled_runs(by_method)
    if labelled is not None:
        summary = labelled_report(s, labelled, runs, seed, console)
    else:
        summary = tracks_report(s, by_method, runs, seed, console)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2))
    if plots:
        from isac_mission.experiment.plots import save_plots

        traces = {m: [trace_path(trace_dir, m, r) for r in range(runs)] for m in methods}
        written = save_plots(traces, out_dir, LABELS)
        console.print("plots: " + ", ".join(str(p) for p in written))
    console.print(f"traces: {trace_dir}/  summary: {out_dir / 'summary.json'}")
    return summary
