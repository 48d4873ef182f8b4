"""Offline commands: `check-config` (derived constants) and `simulate` (Monte Carlo closed loop)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, cast

import typer
from rich.table import Table

from isac_mission.cli.app import ConfigArg, app, console, err_console, load_or_exit
from isac_mission.quiet import quiet_highs_banner

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.planning.slot import Method


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
    for row in rows:
        table.add_row(*row)
    console.print(table)


@app.command()
def simulate(
    config: ConfigArg,
    runs: Annotated[int, typer.Option(min=1, help="Monte Carlo runs.")] = 20,
    seed: Annotated[int | None, typer.Option(help="Base seed (default: the config's).")] = None,
    out: Annotated[
        Path | None, typer.Option(help="Output folder (traces, plots, summary).")
    ] = None,
    methods: Annotated[
        str,
        typer.Option(help="Comma-separated: proposed, proposed-sca, sd, aba, crb, comm, horizon."),
    ] = "proposed,sd,aba,crb,horizon",
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
    from isac_mission.planning.slot import METHODS

    s = load_or_exit(config)
    if live_settings:
        s = _with_live_settings(s)
    chosen = [m.strip() for m in methods.split(",") if m.strip()]
    unknown = sorted(set(chosen) - set(METHODS))
    if unknown or not chosen:
        err_console.print(f"--methods: unknown {unknown}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    quiet_highs_banner()
    out_dir = out if out is not None else Path("out") / f"simulate-{s.mission_id}"
    simulate_report(
        s,
        [cast("Method", m) for m in chosen],
        runs=runs,
        seed=s.seed if seed is None else seed,
        out_dir=out_dir,
        workers=workers,
        plots=plots,
        console=console,
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
