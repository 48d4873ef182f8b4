"""The end of a live mission (`run`, `serve`): what its problems were built as, the verdict, the
summary table (a labelled target's trace) or the tracking tables (a tracks trace), the plots
(experiment/plots.save_plots, as `simulate` writes them) and the trace's path."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from rich.table import Table

from isac_mission.cli.app import console

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.service.assembly import LiveOptions
    from isac_mission.service.mission_result import LiveResult


def print_summary(
    s: Scenario, opts: LiveOptions, result: LiveResult, out_dir: Path, last_slot: int
) -> None:
    """Everything printed after the mission (see the module doc); last_slot: the last slot
    traced, as the progress line last showed it."""
    from isac_mission.nlp_cache import events_summary
    from isac_mission.service.mission_result import summarize_live

    ahead = f"built for {s.M} vehicles and, ahead, for {result.sizes_built_ahead}"
    for line in [ahead, *events_summary(result.planner_problems)]:
        console.print(f"planner problems: {line}", highlight=False)
    _print_verdict(s, opts, result, last_slot)
    from isac_mission.experiment.plots import is_tracks_trace

    if result.trace_path.is_file() and is_tracks_trace(result.trace_path):
        _tracks_summary(s, opts, result, out_dir)
        return
    summary = summarize_live(result)
    table = Table(title=f"{s.mission_id}: live mission summary ({opts.method})")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for name, value in (
        ("slots completed", f"{summary.slots}/{s.N}"),
        ("location RMSE", _figure("{:.3f} m", summary.loc_rmse)),
        ("velocity RMSE", _figure("{:.4f} m/s", summary.vel_rmse)),
        ("mean tr(PCRB)", _figure("{:.4f}", summary.pcrb_mean)),
        (
            "plan solve time median / p95",
            _figure("{:.1f} / {:.1f} ms", summary.solve_median_ms, summary.solve_p95_ms),
        ),
        (
            "detection-to-plan median / p99",
            _figure("{:.1f} / {:.1f} ms", summary.latency_median_ms, summary.latency_p99_ms),
        ),
        ("infeasible slots", str(summary.infeasible)),
        ("fallback slots (method's answer not flown)", str(sum(summary.fallbacks.values()))),
        *((f"fallback: {k}", str(v)) for k, v in sorted(summary.fallbacks.items())),
        *((k, str(v)) for k, v in sorted(result.report.counters.items()) if k != "slots"),
        *((k, str(v)) for k, v in result.fleet_counters.items()),
    ):
        table.add_row(name, value)
    console.print(table)
    if summary.slots:
        from isac_mission.experiment.plots import save_plots

        written = save_plots({opts.method: [result.trace_path]}, out_dir)
        console.print("plots: " + ", ".join(str(p) for p in written))
    console.print(f"trace: {result.trace_path}")


def _figure(spec: str, *values: float) -> str:
    """`spec` filled with `values`, or "-" when one is not finite (no slot measured it)."""
    import math

    return spec.format(*values) if all(math.isfinite(v) for v in values) else "-"


def _print_verdict(s: Scenario, opts: LiveOptions, result: LiveResult, last_slot: int) -> None:
    """The summary's first lines: nominal, interrupted or degraded, why, and what to do
    (cli/verdict.py), for one target or several; last_slot: the last slot traced."""
    import os

    from isac_mission.cli.verdict import MissionFigures, mission_verdict

    counters = {**result.report.counters, **result.fleet_counters}
    statuses = {k.removeprefix("slots "): n for k, n in counters.items() if k.startswith("slots ")}
    figures = MissionFigures(
        slots=counters.get("slots", 0),
        n_slots=s.N,
        statuses=statuses,
        counters=counters,
        vehicles=s.M,
        landed=result.fleet_counters.get("vehicles landed", 0),
        interrupted=result.interrupted,
        landing_abandoned=result.landing_abandoned,
        speed=opts.speed,
        lockstep=opts.lockstep,
        compiled_meanwhile=any("in the background" in e for e in result.planner_problems),
        load_1min=os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        cores=os.cpu_count() or 1,
        last_slot=last_slot,
    )
    verdict = mission_verdict(figures)
    style = {"nominal": "bold green", "interrupted": "bold yellow"}.get(verdict.word, "bold red")
    head, *rest = verdict.lines()
    console.print(f"[{style}]{head}[/]")
    for line in rest:
        console.print(line, highlight=False, markup=False)


def _tracks_summary(s: Scenario, opts: LiveOptions, result: LiveResult, out_dir: Path) -> None:
    """A tracks trace's mission: the tracking tables (as `simulate` prints them, over this one
    run), its counters, and its picture."""
    from isac_mission.experiment.plots import save_plots
    from isac_mission.experiment.report import target_table, tracking_table
    from isac_mission.experiment.track_metrics import summarize_tracking, track_figures

    slots = result.multi_target_slots  # the ground loop's tracked slots (LiveResult's name)
    console.print(f"slots completed: {len(slots)}/{s.N}")
    if slots:
        figures = track_figures(slots, s.multi_tracker.gospa_cutoff_m)
        summaries = {opts.method: summarize_tracking([figures])}
        console.print(tracking_table(summaries, f"{s.mission_id}: live mission, tracking"))
        console.print(target_table(s, summaries))
    counters = Table(title="counters")
    counters.add_column("counter")
    counters.add_column("value", justify="right")
    for k, v in (*sorted(result.report.counters.items()), *result.fleet_counters.items()):
        counters.add_row(k, str(v))
    console.print(counters)
    if slots:
        (png,) = save_plots({opts.method: [result.trace_path]}, out_dir)
        console.print(f"plot: {png}")
    console.print(f"trace: {result.trace_path}")
