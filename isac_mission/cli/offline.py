"""Offline commands: `check-config` (derived constants), `simulate` (Monte Carlo closed loop) and
`replay` (a trace's planner inputs through the offline planner, experiment/replay.py)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from isac_mission.cli.app import ConfigArg, app, console, err_console, load_or_exit
from isac_mission.planning.registry import max_targets, methods_help
from isac_mission.quiet import quiet_highs_banner

if TYPE_CHECKING:
    from isac_mission.config import Scenario

DEFAULT_METHODS = ("proposed", "sd", "aba", "crb", "horizon")


def default_methods(several_targets: bool) -> str:
    """`simulate`'s methods without --methods: DEFAULT_METHODS, on a scenario of several targets
    those the registry says plan for several (Registered.max_targets)."""
    return ",".join(m for m in DEFAULT_METHODS if not several_targets or max_targets(m) != 1)


@app.command("check-config")
def check_config(config: ConfigArg) -> None:
    """Validate a scenario and print its derived constants in SI units."""
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
        ("tracker", _tracker_choice(s), ""),
    ]
    if s.multi_target and s.detection is not None:
        d = s.detection
        rows.append(
            ("detection", f"{d.model}, {d.false_alarms_per_slot:g} false alarms/UAV/slot", "")
        )
    for row in rows:
        table.add_row(*row)
    console.print(table)


def _tracker_choice(s: Scenario) -> str:
    """Which tracker `s` uses and why (tracker.kind; docs/model.md, "Several targets")."""
    from isac_mission.config import multi_target_reasons

    if not s.multi_target:
        return f"labelled EKF (kind {s.tracker_kind})"
    reasons = multi_target_reasons(s)
    why = f": {', '.join(reasons)}" if s.tracker_kind == "auto" and reasons else ""
    return f"multi-target {s.multi_tracker.association.upper()} (kind {s.tracker_kind}{why})"


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
        typer.Option(
            help=f"Comma-separated: {methods_help()}. Default: {default_methods(False)}; on a "
            f"multi-target scenario {default_methods(True)} (the others plan one target)."
        ),
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
) -> None:
    """Offline closed loop (Section II-C) for every method, Monte Carlo with common random numbers."""
    from isac_mission.experiment.report import simulate_report
    from isac_mission.planning.registry import METHODS

    s = load_or_exit(config)
    if live_settings:
        s = _with_live_settings(s)
    default = default_methods(s.multi_target)
    chosen = [m.strip() for m in (methods or default).split(",") if m.strip()]
    unknown = sorted(set(chosen) - set(METHODS))
    if unknown or not chosen:
        err_console.print(f"--methods: unknown {unknown}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    quiet_highs_banner()
    out_dir = out if out is not None else Path("out") / f"simulate-{s.mission_id}"
    if s.multi_target:
        _simulate_multi_target(
            s, chosen, runs, s.seed if seed is None else seed, out_dir, workers, plots
        )
        return
    simulate_report(
        s,
        chosen,
        runs=runs,
        seed=s.seed if seed is None else seed,
        out_dir=out_dir,
        workers=workers,
        plots=plots,
        console=console,
    )


def _simulate_multi_target(
    s: Scenario, methods: list[str], runs: int, seed: int, out_dir: Path, workers: int, plots: bool
) -> None:
    """`simulate` on the multi-target path (experiment/multi_target_report.py)."""
    from isac_mission.errors import ConfigError
    from isac_mission.experiment.multi_target_report import multi_target_report
    from isac_mission.planning.multi_target import check_multi_target_method

    try:
        for m in methods:
            check_multi_target_method(m)
    except ConfigError as err:
        err_console.print(f"--methods: {err}", highlight=False)
        raise typer.Exit(2) from None
    multi_target_report(
        s,
        methods,
        runs=runs,
        seed=seed,
        out_dir=out_dir,
        workers=workers,
        console=console,
        plots=plots,
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

    s = load_or_exit(config, single_target_only=True)
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
    if not any(r.plan_start_xy is not None for r in recorded.slots):
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
