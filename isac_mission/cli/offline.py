"""Offline commands: `check-config` (derived constants), `simulate` (Monte Carlo closed loop) and
`replay` (a trace's planner inputs through the offline planner, experiment/replay.py)."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from isac_mission.cli.app import ConfigArg, app, console, err_console, load_or_exit
from isac_mission.cli.planner_options import (
    PlannerDeadlineOpt,
    PlannerSchedulerOpt,
    PlannerWorkersOpt,
    checked_planner_cluster,
)
from isac_mission.planning.registry import max_targets, methods_help
from isac_mission.quiet import quiet_highs_banner

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.planner_cluster import PlannerCluster

DEFAULT_METHODS = ("proposed", "sd", "aba", "crb", "horizon")


def default_methods(s: Scenario) -> str:
    """`simulate`'s methods without --methods: those of DEFAULT_METHODS that can plan for the
    scenario's tracks (planning/tracks.method_problem: on a scenario of several targets, those
    the registry says plan for several, Registered.max_targets)."""
    from isac_mission.planning.tracks import method_problem

    return ",".join(m for m in DEFAULT_METHODS if method_problem(s, m) is None)


METHODS_HELP_DEFAULT = (
    f"Default: {','.join(DEFAULT_METHODS)}; on a multi-target scenario "
    f"{','.join(m for m in DEFAULT_METHODS if max_targets(m) != 1)} (the others plan one target)."
)


@app.command("check-config")
def check_config(config: ConfigArg) -> None:
    """Validate a scenario and print its derived constants in SI units."""
    from isac_mission.tracking.factory import detection_description, tracker_description

    s = load_or_exit(config)
    table = Table(title=f"{config} (mission {s.mission_id})")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_column("unit")
    rows = [
        ("M UAVs / K BSs / N slots", f"{s.M} / {s.K} / {s.N}", ""),
        ("wavelength", f"{s.wavelength * 1e3:.3f}", "mm"),
        ("beta0", f"{s.beta0:.3e}", ""),
        ("rho0 = Pu beta0 / sigma0^2", f"{s.rho0:.3e}", "m^2"),
        ("control range d_th", f"{s.d_th:.1f}", "m"),
        ("Gamma_th", f"{s.gamma_th:.2f}", ""),
        ("R_th", f"{s.r_th / 1e6:.2f}", "Mbit/s"),
        ("sensing model", s.sensing_model, ""),
        ("alpha_d", f"{s.alpha_d:.3e}", "m^2 Hz^2"),
        ("alpha_v", f"{s.alpha_v:.3e}", "m^2/s^2 s^2"),
        ("T^s", f"{s.Ts:g}", "s"),
        ("radar gain c0 (SNR^s = c0/d^4)", f"{s.radar_gain:.3e}", "m^4"),
        ("BS positions", str(s.bs_xy.round(1).tolist()), "m"),
    ]
    rows += [
        (
            f"target {t.name}",
            f"{t.motion}, slots {t.first_slot}-{t.last_slot}, "
            f"{'known' if t.prior_known else 'unknown'}",
            "",
        )
        for t in s.targets
    ]
    rows += [
        ("kappa (target_motion)", f"{s.kappa:g}", "m^2/s^3"),
        ("a_T (target_motion)", f"{s.a_target:g}", "m/s^2"),
        ("tracker", tracker_description(s), ""),
    ]
    detection = detection_description(s)
    if detection is not None:
        rows.append(("detection", detection, ""))
    for row in rows:
        table.add_row(*row)
    console.print(table)


@app.command()
def simulate(
    config: ConfigArg,
    runs: Annotated[int, typer.Option(min=1, help="Monte Carlo runs.")] = 20,
    seed: Annotated[
        int | None, typer.Option(min=0, help="Base seed (default: the config's).")
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help="Output folder (traces, plots, summary).")
    ] = None,
    methods: Annotated[
        str | None,
        typer.Option(help=f"Comma-separated: {methods_help()}. {METHODS_HELP_DEFAULT}"),
    ] = None,
    workers: Annotated[int, typer.Option(min=1, help="Worker processes.")] = 2,
    plots: Annotated[bool, typer.Option(help="Write the Fig. 2 / Fig. 3 style PNGs.")] = True,
    live_settings: Annotated[
        bool,
        typer.Option(
            "--live-settings",
            help="Plan with exactly what `run` and `serve` plan with (margins, vehicle model; "
            "docs/model.md, 'Live service').",
        ),
    ] = False,
    planner_workers: PlannerWorkersOpt = 0,
    planner_scheduler: PlannerSchedulerOpt = None,
    planner_deadline: PlannerDeadlineOpt = None,
) -> None:
    """Offline closed loop (Section II-C) for every method, Monte Carlo with common random numbers."""
    from isac_mission.experiment.report import simulate_report
    from isac_mission.planning.registry import METHODS
    from isac_mission.planning.tracks import method_problem

    s = load_or_exit(config)
    if live_settings:
        s = _with_live_settings(s)
    chosen = [m.strip() for m in (methods or default_methods(s)).split(",") if m.strip()]
    unknown = sorted(set(chosen) - set(METHODS))
    if unknown or not chosen:
        err_console.print(f"--methods: unknown {unknown}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    problem = next((p for m in chosen if (p := method_problem(s, m)) is not None), None)
    if problem is not None:
        err_console.print(f"--methods: {problem}", highlight=False)
        raise typer.Exit(2)
    report = partial(
        simulate_report,
        s,
        chosen,
        runs=runs,
        seed=s.seed if seed is None else seed,
        out_dir=out if out is not None else Path("out") / f"simulate-{s.mission_id}",
        plots=plots,
        console=console,
    )
    cluster = checked_planner_cluster(
        s,
        chosen,
        "add it to --methods",
        planner_workers,
        planner_scheduler,
        planner_deadline,
    )
    if cluster is None:
        quiet_highs_banner()
        report(workers=workers)
        return
    _simulate_on_planner_cluster(s, report, cluster)


def _simulate_on_planner_cluster(
    s: Scenario, report: Callable[..., object], cluster: PlannerCluster
) -> None:
    """`report` (the simulation) with the decomposed horizon's groups solved on `cluster`
    (isac_mission/planner_cluster.py; its deadline `deadline_for()`, 120 s by default): the
    runs flown in this process, the executor set on the kit they plan with
    (experiment/runs.kit_for, one per scenario and process) for the simulation and taken off
    after it."""
    from rich.markup import escape

    from isac_mission.experiment.runs import kit_for
    from isac_mission.planner_cluster import cluster_description
    from isac_mission.planning.decomposed import use_group_executor

    console.print(
        f"planner: the decomposed horizon's groups solved on {escape(cluster.where)}, "
        f"deadline {cluster.deadline_for():g} s a slot; the runs flown in this process",
        highlight=False,
    )
    quiet_highs_banner()
    kit = kit_for(s)
    with cluster.executor() as executor:
        console.print(f"planner cluster: {cluster_description(executor.client)}")
        use_group_executor(kit, executor)
        try:
            report(workers=1)
        finally:
            use_group_executor(kit, None)
    lost = f", last: {escape(executor.last_error)}" if executor.failures else ""
    console.print(
        f"planner cluster: {executor.slots} slots' groups solved on it, {executor.failures} "
        f"flew the per-slot plan (decomposed worker lost){lost}",
        highlight=False,
    )


def _with_live_settings(s: Scenario) -> Scenario:
    """`s` with the live service's planning settings, and a table of what they change."""
    from isac_mission.config.live_settings import LIVE_SETTINGS

    table = Table(title="live settings (as `run` and `serve` plan)")
    for col in ("quantity", "scenario", "live"):
        table.add_column(col)
    for row in LIVE_SETTINGS.changes(s):
        table.add_row(*row)
    console.print(table)
    return LIVE_SETTINGS.apply(s)


@app.command()
def replay(
    config: ConfigArg,
    trace: Annotated[
        Path, typer.Argument(help="A trace of `run`, `serve` or `simulate` (docs/trace.md).")
    ],
    from_slot: Annotated[
        int, typer.Option(min=1, help="Summarise slots from this one on too (tracking phase).")
    ] = 11,
    out: Annotated[
        Path | None, typer.Option(help="Write the per-slot rows and the summaries as JSON.")
    ] = None,
) -> None:
    """Replay a trace's planner inputs through the offline planner: where each slot's plan
    started against where the offline loop starts, and whether the same planner makes the same
    plan (docs/performance.md, "Live against offline")."""
    import json
    from dataclasses import asdict

    from isac_mission.config.live_settings import LIVE_SETTINGS
    from isac_mission.errors import IsacError
    from isac_mission.experiment.replay import (
        config_differences,
        replay_trace,
        summarize_replay,
    )
    from isac_mission.records import read_trace

    s = load_or_exit(config)
    quiet_highs_banner()
    try:
        recorded = read_trace(trace)
    except (OSError, IsacError) as err:
        err_console.print(f"[bold red]cannot read the trace {trace}:[/] {err}")
        raise typer.Exit(1) from None
    candidates = [s, LIVE_SETTINGS.apply(s)]
    planning = next((c for c in candidates if not config_differences(recorded.config, c)), None)
    if planning is None:
        diffs = [config_differences(recorded.config, c) for c in candidates]
        live = len(diffs[1]) < len(diffs[0])
        err_console.print(
            f"[bold red]{config} does not give the scenario {trace} was planned with"
            f"{' (with the live settings)' if live else ''}:[/] " + "; ".join(diffs[live])
        )
        raise typer.Exit(1)
    if not any(line.line.get("plan_start_xy") is not None for line in recorded.lines):
        err_console.print(
            f"[bold red]{trace} records no planner inputs (plan_start_xy): written by an "
            "older isac-mission?[/]"
        )
        raise typer.Exit(1)
    rows = replay_trace(recorded, planning)
    table = Table(title=f"replay of {trace} ({recorded.method}), per UAV mean")
    for col in ("slot", "status", "start gap m", "v gap m/s", "replay gap m", "step m",
                "from offline start m", "fallback (replay)"):  # fmt: skip
        table.add_column(col, justify="left" if col in ("status", "fallback (replay)") else "right")
    for r in rows:
        fb = r.fallback or "-"
        if r.replay_fallback != r.fallback:
            fb += f" ({r.replay_fallback or '-'})"
        table.add_row(
            str(r.slot),
            r.status,
            f"{r.start_gap_m.mean():.2f}",
            f"{r.start_velocity_gap_mps.mean():.2f}",
            f"{r.replay_gap_m.mean():.3f}",
            f"{r.planned_step_m.mean():.2f}",
            f"{r.offline_step_m.mean():.2f}",
            fb,
        )
    console.print(table)
    summaries = {f"slots {first}..": summarize_replay(rows, first) for first in (1, from_slot)}
    sums = Table(title="summary: mean (max) per UAV-slot")
    for col in ("slots", "n", "start gap m", "v gap m/s", "prediction gap", "replay gap m",
                "step m", "from offline start m", "fallbacks (replay)"):  # fmt: skip
        sums.add_column(col, justify="right")
    for name, v in summaries.items():
        sums.add_row(
            name,
            str(v.slots),
            f"{v.start_gap_m:.2f} ({v.start_gap_max_m:.2f})",
            f"{v.start_velocity_gap_mps:.2f}",
            f"{v.prediction_gap_max:.2g}",
            f"{v.replay_gap_m:.3f} ({v.replay_gap_max_m:.3f})",
            f"{v.planned_step_m:.2f}",
            f"{v.offline_step_m:.2f}",
            f"{v.fallbacks} ({v.replay_fallbacks})",
        )
    console.print(sums)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(
            json.dumps(
                {
                    "trace": str(trace),
                    "slots": [r.to_dict() for r in rows],
                    "summaries": {k: asdict(v) for k, v in summaries.items()},
                },
                indent=2,
            )
        )
        console.print(f"replay: {out}")
