"""The `isac-mission` Typer application, its consoles, and what every command group shares.

Bad input gets one line on stderr naming what is wrong, and exit status 2: Click's usage errors
(an unknown option, a value that does not parse or is out of range) through `OneLineErrors`,
the commands' own checks through `err_console` (which never wraps a line). `--help` is Click's
plain help, which wraps the help texts and never cuts an option's name. Every numeric option
declares its range: `min=` / `max=` (integers) or a `number_check` callback (floats).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from typer.core import TyperGroup

from isac_mission.config import Scenario, load_scenario
from isac_mission.config.loading import scenario_names
from isac_mission.errors import ConfigError

console = Console()
err_console = Console(stderr=True, soft_wrap=True)
"""stderr; soft_wrap: a message is one line whatever the terminal's width."""


def _option_name(param: Any) -> str:
    """How a message names a parameter: its long option (`--speed`), else its first option, else
    the argument's name in capitals (`CONFIG`)."""
    opts = [str(o) for o in getattr(param, "opts", ())]
    longs = [o for o in opts if o.startswith("--")]
    if longs:
        return longs[0]
    if opts and opts[0].startswith("-"):
        return opts[0]
    return str(getattr(param, "name", "") or "argument").upper()


def error_line(err: typer.TyperException) -> str:
    """One line for a Click usage error: `--runs: input should be greater than or equal to 1,
    got 0` for a bad value (the option, what is wrong, the value given), else `isac-mission run:
    No such option: --bogus (...); see 'isac-mission run --help'`."""
    param = getattr(err, "param", None)
    # A bad value; not BadParameter's subclass MissingParameter, whose message names the option.
    bad_value = type(err).__name__ == "BadParameter"
    if isinstance(err, typer.BadParameter) and param is not None and bad_value:
        message = err.message
        errors = getattr(err.__cause__, "errors", None)
        if callable(errors):  # typer's own parsing (pydantic): add the value given
            first = errors()
            if first:
                value = first[0].get("input")
                message = f"{message[:1].lower()}{message[1:]}, got {value}"
        line = f"{_option_name(param)}: {message}"
    else:
        ctx = getattr(err, "ctx", None)
        where = ctx.command_path if ctx is not None else "isac-mission"
        line = f"{where}: {err.format_message().rstrip('.')}; see '{where} --help'"
    return " ".join(line.split())


@contextmanager
def _one_line_errors() -> Iterator[None]:
    """Turn a Click usage error into `error_line` on stderr and its exit status (2); a call
    without arguments still shows the help."""
    try:
        yield
    except typer.TyperException as err:
        if type(err).__name__ == "NoArgsIsHelpError":  # Click shows the help for it
            raise
        err_console.print(error_line(err), markup=False, highlight=False)
        raise typer.Exit(getattr(err, "exit_code", 2)) from None


class OneLineErrors(TyperGroup):
    """The command group: Click's usage errors, raised while it parses the group's or a
    command's arguments or while a command runs, become one line (`error_line`) and exit 2."""

    def make_context(
        self,
        info_name: str | None,
        args: list[str],
        parent: Any = None,
        **extra: Any,
    ) -> Any:
        with _one_line_errors():
            return super().make_context(info_name, args, parent, **extra)

    def invoke(self, ctx: Any) -> Any:
        with _one_line_errors():
            return super().invoke(ctx)


app = typer.Typer(
    cls=OneLineErrors,
    add_completion=False,
    no_args_is_help=True,
    # Click's plain help: rich's panels cut option names at 80 columns.
    rich_markup_mode=None,
    help="ISAC multi-UAV collaborative target tracking (PCRB-optimal trajectories and bandwidth).",
)


def number_check(
    *,
    above: float | None = None,
    at_least: float | None = None,
    allow_inf: bool = False,
) -> Callable[[float | None], float | None]:
    """A typer callback for a float option: the value must be > `above` (or >= `at_least`),
    and finite unless `allow_inf` (then +inf too); NaN never passes. The message names the rule
    and the value (`must be > 0 (or inf), got -2.0`); None (an option not given) passes."""

    bound = f"> {above:g}" if above is not None else ""
    bound = bound or (f">= {at_least:g}" if at_least is not None else "")
    if allow_inf:
        rule = f"must be {bound or 'a number'} (or inf)"
    else:
        rule = f"must be {bound} and finite" if bound else "must be finite"

    def check(value: float | None) -> float | None:
        if value is None:
            return None
        ok = not math.isnan(value) and ((allow_inf and value == math.inf) or math.isfinite(value))
        if ok and above is not None:
            ok = value > above
        if ok and at_least is not None:
            ok = value >= at_least
        if not ok:
            raise typer.BadParameter(f"{rule}, got {value}")
        return value

    return check


ConfigArg = Annotated[
    Path,
    typer.Argument(
        help="Scenario YAML file (e.g. config/paper.yaml), or the name of a shipped scenario "
        f"({', '.join(scenario_names())})."
    ),
]

PlanBudgetOpt = Annotated[
    float,
    typer.Option(
        callback=number_check(at_least=0.0),
        help="Wall seconds a slot's planning may take; past it the slot holds (>= 0; 0: no limit).",
    ),
]
SpeedOpt = Annotated[
    float,
    typer.Option(
        callback=number_check(above=0.0, allow_inf=True),
        help="Simulation seconds per wall second (> 0; inf: as fast as possible).",
    ),
]
SeedOpt = Annotated[
    int | None, typer.Option(min=0, help="World noise seed (default: the config's).")
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
LiveConsoleOpt = Annotated[
    str | None,
    typer.Option(
        "--console",
        help="Serve the operator console on HOST:PORT (loopback unless --console-public; "
        "default 127.0.0.1:8080, + --port-offset).",
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


def load_or_exit(path: Path) -> Scenario:
    """Load a scenario or print its problem (one line; several problems one per line) and exit
    with status 2. A deprecated section is one `deprecated:` line on stderr each (the scenario
    still loads)."""
    from rich.markup import escape

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DeprecationWarning)
        try:
            s = load_scenario(path)
        except ConfigError as err:
            err_console.print(
                f"[bold red]invalid configuration:[/] {escape(str(err))}", highlight=False
            )
            raise typer.Exit(2) from None
    for w in caught:
        if issubclass(w.category, DeprecationWarning):
            err_console.print(
                f"[bold yellow]deprecated:[/] {escape(str(w.message))}", highlight=False
            )
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
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
