"""`simulate` on a multi-target scenario (docs/model.md, "Several targets"): every method on the
same runs (common random numbers), the tracking figures per method, each method's GOSPA
against the first method's (`proposed` by default) as a % change with its paired bootstrap
interval (comparison.change_convention: negative = lower, better), the traces (docs/trace.md,
"Multi-target traces") and summary.json.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from isac_mission.config import Scenario
from isac_mission.experiment.bootstrap import (
    change_of_means,
    paired_bootstrap,
    reduction_of_means,
)
from isac_mission.experiment.comparison import NEEDS_TWO_RUNS, Change, change_convention
from isac_mission.experiment.multi_target_loop import run_multi_target
from isac_mission.experiment.multi_target_metrics import (
    RunFigures,
    TrackingSummary,
    run_figures,
    summarize_tracking,
)
from isac_mission.experiment.multi_target_plots import save_tracks_png
from isac_mission.experiment.report import (
    change_cell,
    missing_caption,
    print_table,
    runs_text,
)
from isac_mission.model.run_noise import draw_multi_target_noise
from isac_mission.planning.multi_target import check_multi_target_method, multi_target_kit
from isac_mission.planning.registry import LABELS
from isac_mission.records.jsonlines import to_jsonable
from isac_mission.records.multi_target import TRACE_FORMAT, header_line, slot_line

__all__ = ["TRACE_FORMAT", "multi_target_report", "run_multi_target_monte_carlo"]


@dataclass(frozen=True)
class MethodRuns:
    """One method's runs: figures [R] and plan times (s) of every slot of every run."""

    method: str
    figures: tuple[RunFigures, ...]
    solve_s: tuple[float, ...]


def _one_run(s: Scenario, method: str, run: int, seed: int, trace_dir: Path | None) -> MethodRuns:
    noise = draw_multi_target_noise(s, seed + run)
    kit = multi_target_kit(s)
    lines: list[str] = []
    result = run_multi_target(s, method, noise, kit, lambda o: lines.append(slot_line(o)))
    if trace_dir is not None:
        config = s.trace_config() | {"seed": seed + run, "method": method}
        head = header_line(config)
        path = trace_dir / f"{method}_run{run:03d}.jsonl"
        path.write_text("\n".join([head, *lines]) + "\n")
    figures = run_figures(result, s.multi_tracker.gospa_cutoff_m)
    return MethodRuns(method, (figures,), tuple(o.plan.report.solve_s for o in result.slots))


def run_multi_target_monte_carlo(
    s: Scenario,
    methods: Sequence[str],
    runs: int,
    seed: int,
    trace_dir: Path | None = None,
    workers: int = 1,
) -> dict[str, MethodRuns]:
    """Every method on runs 0..runs-1 (noise seed = seed + run), in `workers` processes."""
    for m in methods:
        check_multi_target_method(m)
    if trace_dir is not None:
        trace_dir.mkdir(parents=True, exist_ok=True)
    jobs = [(m, r) for r in range(runs) for m in methods]
    if workers <= 1:
        done = [_one_run(s, m, r, seed, trace_dir) for m, r in jobs]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(_one_run, s, m, r, seed, trace_dir) for m, r in jobs]
            done = [f.result() for f in futures]
    out: dict[str, MethodRuns] = {}
    for m in methods:
        mine = [d for d in done if d.method == m]
        out[m] = MethodRuns(
            m,
            tuple(f for d in mine for f in d.figures),
            tuple(t for d in mine for t in d.solve_s),
        )
    return out


def tracking_table(s: Scenario, summaries: dict[str, TrackingSummary], title: str) -> Table:
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


def target_table(s: Scenario, summaries: dict[str, TrackingSummary]) -> Table:
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
    by_method: Mapping[str, MethodRuns], reference: str, runs: int, seed: int
) -> tuple[Table, dict[str, Any]]:
    """Each method's mission-mean GOSPA against `reference`'s as a % change (change_of_means:
    negative = lower, better), paired bootstrap 95 % interval over runs (none with one run: the
    caption says so), and plan time median (ms). Returns the table and summary.json's
    `against_baseline` rows: `gospa_change_pct` [estimate, low, high] (low, high None with one
    run) and `gospa_reduction_pct` (the reduction, the opposite sign; None with one run)."""
    ref = LABELS.get(reference, reference)
    base = np.array([f.gospa_m.mean() for f in by_method[reference].figures])
    changes: dict[str, Change] = {}
    rows: dict[str, Any] = {}
    for m, r in by_method.items():
        g = np.array([f.gospa_m.mean() for f in r.figures])
        reduction: list[float] | None = None
        if runs >= 2:
            iv = paired_bootstrap(base, g, change_of_means, seed=seed)
            c = Change(iv.estimate, iv)
            red = paired_bootstrap(base, g, reduction_of_means, seed=seed)
            reduction = [red.estimate, red.low, red.high]
        else:
            c = Change(float(change_of_means(base, g)), None, NEEDS_TWO_RUNS)
        changes[m] = c
        rows[m] = {
            "gospa_reduction_pct": reduction,
            "gospa_change_pct": [
                c.estimate,
                None if c.interval is None else c.interval.low,
                None if c.interval is None else c.interval.high,
            ],
            "plan_time_median_ms": 1e3 * float(np.median(r.solve_s)),
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


def multi_target_report(
    s: Scenario,
    methods: Sequence[str],
    *,
    runs: int,
    seed: int,
    out_dir: Path,
    workers: int,
    console: Console,
    plots: bool = True,
) -> dict[str, Any]:
    """Run, print the tables, write the traces, summary.json and (plots) each method's first
    run's picture, tracks_<method>.png, under out_dir; returns the summary."""
    by_method = run_multi_target_monte_carlo(
        s, methods, runs, seed, out_dir / "traces", workers=workers
    )
    summaries = {m: summarize_tracking(r.figures) for m, r in by_method.items()}
    title = (
        f"{s.mission_id}: {runs_text(runs)}, {len(s.targets)} targets, "
        f"seeds {seed}..{seed + runs - 1}"
    )
    print_table(console, tracking_table(s, summaries, title))
    print_table(console, target_table(s, summaries))
    against, rows = gospa_against_reference(by_method, methods[0], runs, seed)
    print_table(console, against)
    summary = {
        "scenario": s.mission_id,
        "runs": runs,
        "seed": seed,
        "methods": {m: to_jsonable(vars(x)) for m, x in summaries.items()},
        "against_baseline": rows,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "summary.json").write_text(json.dumps(to_jsonable(summary), indent=1))
    if plots:
        for m in methods:
            save_tracks_png(out_dir / "traces" / f"{m}_run000.jsonl", out_dir / f"tracks_{m}.png")
    console.print(f"traces and summary.json in {out_dir}")
    return summary
