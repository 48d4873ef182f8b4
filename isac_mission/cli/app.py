"""The `isac-mission` Typer application, its consoles, and what every command group shares."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from isac_mission.config import Scenario, load_scenario, single_target_problem
from isac_mission.errors import ConfigError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="ISAC multi-UAV collaborative target tracking (PCRB-optimal trajectories and bandwidth).",
)
console = Console()
err_console = Console(stderr=True)

ConfigArg = Annotated[
    Path,
    typer.Argument(
        help="Scenario YAML file (e.g. config/paper.yaml), or the name of a shipped scenario "
        "(paper, paper-literal, constrained, multi-target)."
    ),
]

PlanBudgetOpt = Annotated[
    float,
    typer.Option(
        help="Wall seconds a slot's planning may take; past it the slot holds (0: no limit)."
    ),
]
InjectLinkLossOpt = Annotated[
    list[str] | None,
    typer.Option(
        help="Fault injection: vehicle M's MAVLink radio dies START_S into the mission for "
        "DURATION_S, as M:START_S:DURATION_S (repeatable; docs/reliability.md)."
    ),
]

ImpairLinkOpt = Annotated[
    list[str] | None,
    typer.Option(
        help="Fault injection: lossy, late links of the simulated world, as "
        "[TARGET[:up|down]:]KEY=VALUE,... with TARGET all (default), a vehicle index or "
        "detections and KEY loss, latency_ms, jitter_ms, duplicate, reorder, reorder_delay_ms, "
        "e.g. loss=0.2,latency_ms=100,jitter_ms=50 (repeatable; over the scenario's "
        "`impairment` section; docs/reliability.md)."
    ),
]
ConsoleOpt = Annotated[
    str,
    typer.Option(
        "--console",
        help="Serve the operator console on HOST:PORT (loopback unless --console-public).",
    ),
]
NoConsoleOpt = Annotated[bool, typer.Option("--no-console", help="Do not serve the console.")]
PublicOpt = Annotated[
    bool,
    typer.Option(
        "--console-public",
        help="Allow a non-loopback --console address (the page can command the fleet).",
    ),
]


def load_or_exit(path: Path, single_target_only: bool = False) -> Scenario:
    """Load a scenario or print its problems (one per line) and exit with status 2; with
    `single_target_only`, a multi-target scenario is refused too (`single_target_problem`)."""
    try:
        s = load_scenario(path)
    except ConfigError as err:
        err_console.print(f"[bold red]invalid configuration[/]\n{err}", highlight=False)
        raise typer.Exit(2) from None
    problem = single_target_problem(s) if single_target_only else None
    if problem is not None:
        err_console.print(f"[bold red]not supported yet[/]\n{path}: {problem}", highlight=False)
        raise typer.Exit(2)
    return s


def _print_version(value: bool) -> None:
    """Eager `--version`: print the package version and exit."""
    if value:
        from isac_mission import __version__

        console.print(f"isac-mission {__version__}", highlight=False)
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_print_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """ISAC multi-UAV collaborative target tracking (PCRB-optimal trajectories and bandwidth)."""
