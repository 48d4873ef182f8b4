"""The `isac-mission` command line: simulate, check-config (and the live commands)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from isac_mission.config import Scenario, load_scenario
from isac_mission.errors import ConfigError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="ISAC multi-UAV collaborative target tracking (PCRB-optimal trajectories and bandwidth).",
)
console = Console()
err_console = Console(stderr=True)

ConfigArg = Annotated[Path, typer.Argument(help="Scenario YAML file, e.g. config/paper.yaml.")]


def load_or_exit(path: Path) -> Scenario:
    """Load a scenario or print its problems (one per line) and exit with status 2."""
    try:
        return load_scenario(path)
    except ConfigError as err:
        err_console.print(f"[bold red]invalid configuration[/]\n{err}", highlight=False)
        raise typer.Exit(2) from None


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


def main() -> None:
    """Console-script entry point."""
    sys.exit(app())


if __name__ == "__main__":
    main()
