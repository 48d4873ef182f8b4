"""`isac-mission run` (world, bridges and ground loop in one process), `serve` (bridges and
ground loop only) and `compile`: their options, checked and resolved into the service's settings
(`isac_mission.service.assembly.LiveOptions`); the mission, its progress line and Ctrl-C are
`cli/mission.py`'s, the end of the mission is printed by `cli/summary.py`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from isac_mission.cli.app import (
    ConfigArg,
    ImpairLinkOpt,
    InjectLinkLossOpt,
    LiveConsoleOpt,
    NoConsoleOpt,
    PlanBudgetOpt,
    PublicOpt,
    SeedOpt,
    SpeedOpt,
    app,
    console,
    err_console,
    load_or_exit,
)
from isac_mission.cli.planner_options import (
    PlannerDeadlineOpt,
    PlannerSchedulerOpt,
    PlannerWorkersOpt,
    checked_planner_cluster,
)
from isac_mission.cli.ports import (
    ZENOH_LISTEN_HINT,
    ZENOH_PORT_HINT,
    GcsLocalBasePortOpt,
    GcsPortOpt,
    MavlinkBasePortOpt,
    MavlinkLocalBasePortOpt,
    PortOffsetOpt,
    PortOptionError,
    ServeMavlinkBasePortOpt,
    mission_ports,
)
from isac_mission.planning.registry import methods_help
from isac_mission.quiet import quiet_highs_banner

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.service.assembly import LiveOptions


def resolved_method(method: str | None, s: Scenario, out_dir: Path, resume: bool) -> str:
    """--method if given; else, resuming, the method of the one trace in out_dir
    (trace_<method>.jsonl: `serve --resume` continues what was flown), else the live default
    (`planning/tracks.live_method`). ValueError when out_dir holds the traces of several
    methods."""
    from isac_mission.planning.tracks import live_method

    if method is not None:
        return method
    if resume:
        found = sorted(
            p.name[len("trace_") : -len(".jsonl")] for p in out_dir.glob("trace_*.jsonl")
        )
        if len(found) > 1:
            raise ValueError(
                f"{out_dir} holds the traces of {', '.join(found)}; say which to resume"
            )
        if found:
            return found[0]
    return live_method(s)


def resume_problem(s: Scenario, trace: Path, method: str) -> str | None:
    """Why `serve --resume` must not continue `trace` for `s` flown with `method` (None: it
    may): the trace is complete (its last slot is N: nothing left to fly), or it does not read;
    or the trace's own refusal (service/ground/tracefile.py `resume_refusal`: a trace of tracks
    that is not this mission's, method's and configuration's, or whose last slot line lacks what
    a restart needs). Reads the file, never writes it."""
    from isac_mission.errors import MessageError
    from isac_mission.records.progress import trace_progress

    if not trace.exists():
        return None
    try:
        progress = trace_progress(trace)
    except MessageError as err:
        return f"cannot continue {trace}: {err}"
    if progress.last_slot >= s.N:
        return (
            f"the trace is complete: {progress.last_slot}/{s.N} slots in {trace}; nothing "
            "to resume (start a new mission without --resume, or in another --out)"
        )
    from isac_mission.service.assembly import LiveOptions, live_trace_limits, planning_scenario
    from isac_mission.service.ground.tracefile import live_trace_config, resume_refusal

    # The config line the mission would write: it plans with the live settings.
    planning = planning_scenario(s, LiveOptions())
    config = live_trace_config(planning, method, live_trace_limits(s, planning))
    return resume_refusal(planning, trace, config)


@dataclass(frozen=True)
class LiveCommand:
    """What `run` or `serve` was given, before the scenario resolves it (None: the default).

    serve_only: `serve` (the world runs elsewhere) rather than `run`; method: `--method`
    (`resolved_method`); out: the output folder (default out/run-<mission> or
    out/serve-<mission>); zenoh_listen, zenoh_connect, the MAVLink and ground-station ports and
    port_offset: `cli/ports.py`'s `mission_ports`; plan_budget_s: wall seconds a slot's planning
    may take (<= 0: no limit); link_outages, link_impairment: the embedded world's
    `--inject-link-loss` and `--impair-link`; vehicle_links: `serve --vehicle-link`;
    serve_console, console_address, console_public: the live console (default address
    127.0.0.1:8080 + port_offset); planner_workers, planner_scheduler, planner_deadline_s:
    the planner cluster (`cli/planner_options.py`; 0, None, None: none)."""

    config: Path
    serve_only: bool
    speed: float = 1.0
    lockstep: bool = False
    method: str | None = None
    seed: int | None = None
    out: Path | None = None
    zenoh_listen: str | None = None
    zenoh_connect: tuple[str, ...] = ()
    mavlink_base_port: int | None = None
    mavlink_local_base_port: int | None = None
    gcs_port: int | None = None
    gcs_local_base_port: int | None = None
    port_offset: int = 0
    resume: bool = False
    plan_budget_s: float = 1.0
    link_outages: tuple[str, ...] = ()
    link_impairment: tuple[str, ...] = ()
    vehicle_links: tuple[str, ...] = ()
    serve_console: bool = False
    console_address: str | None = None
    console_public: bool = False
    planner_workers: int = 0
    planner_scheduler: str | None = None
    planner_deadline_s: float | None = None


def _live(command: LiveCommand) -> None:
    """Shared body of `run` and `serve`: the options checked and resolved into the service's
    settings, then the mission with its console, live progress, summary and plots
    (`cli/mission.py`); exit 0 on SIGINT/SIGTERM. Bad input (an option, a port in use, a finished
    trace to resume) exits 2 with one line, before anything is opened."""
    from isac_mission.cli.mission import fly

    s = load_or_exit(command.config)
    opts, console_address = _checked_options(command, s)
    fly(
        s,
        opts,
        embedded=not command.serve_only,
        console_address=console_address if command.serve_console else None,
        console_public=command.console_public,
    )


def _checked_options(command: LiveCommand, s: Scenario) -> tuple[LiveOptions, str]:
    """`command` checked against `s` and resolved into the service's settings, with the live
    console's address; bad input exits 2 with one line. Sets up logging and quiets the HiGHS
    banner once the ports are known to be free."""
    import logging

    from isac_mission.bus.session import check_listen_endpoints
    from isac_mission.errors import PortInUseError
    from isac_mission.planning.registry import METHODS
    from isac_mission.service.assembly import LiveOptions

    try:
        ports = mission_ports(
            s,
            command.port_offset,
            zenoh=command.zenoh_listen,
            console=command.console_address,
            mavlink_base_port=command.mavlink_base_port,
            mavlink_local_base_port=command.mavlink_local_base_port,
            gcs_port=command.gcs_port,
            gcs_local_base_port=command.gcs_local_base_port,
        )
    except PortOptionError as err:
        err_console.print(str(err), highlight=False, markup=False)
        raise typer.Exit(2) from None
    out_dir = (
        command.out
        if command.out is not None
        else Path("out") / f"{'serve' if command.serve_only else 'run'}-{s.mission_id}"
    )
    try:
        method = resolved_method(command.method, s, out_dir, command.resume)
    except ValueError as err:
        err_console.print(f"--method: {err}", highlight=False)
        raise typer.Exit(2) from None
    if method not in METHODS:
        err_console.print(f"--method: unknown {method!r}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    from isac_mission.planning.tracks import method_problem

    problem = method_problem(s, method)
    if problem is not None:
        err_console.print(f"--method: {problem}", highlight=False)
        raise typer.Exit(2)
    planner_cluster = checked_planner_cluster(
        s,
        [method],
        f"this mission flies `{method}` (--method horizon)",
        command.planner_workers,
        command.planner_scheduler,
        command.planner_deadline_s,
    )
    if command.resume:
        problem = resume_problem(s, out_dir / f"trace_{method}.jsonl", method)
        if problem is not None:
            err_console.print(f"--resume: {problem}", highlight=False, markup=False)
            raise typer.Exit(2)
    try:
        check_listen_endpoints((ports.zenoh,))
    except PortInUseError as err:
        hint = ZENOH_PORT_HINT if command.zenoh_listen is None else ZENOH_LISTEN_HINT
        err_console.print(f"{err}; {hint}", highlight=False, markup=False)
        raise typer.Exit(2) from None
    quiet_highs_banner()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    if command.link_outages:
        from isac_mission.cli.embedded import check_link_outages

        try:
            check_link_outages(command.link_outages, s.M)
        except ValueError as err:
            err_console.print(f"--inject-link-loss: {err}", highlight=False)
            raise typer.Exit(2) from None
    if command.link_impairment:
        from isac_mission.cli.embedded import world_impairment
        from isac_mission.errors import ConfigError

        try:
            world_impairment(s, command.link_impairment)
        except ConfigError as err:
            err_console.print(f"[bold red]invalid option[/] {err}", highlight=False)
            raise typer.Exit(2) from None
    if command.vehicle_links:
        from isac_mission.mavwire.serial_link import parse_vehicle_links

        try:
            parse_vehicle_links(command.vehicle_links, s.M)
        except ValueError as err:
            err_console.print(f"--vehicle-link: {err}", highlight=False)
            raise typer.Exit(2) from None
    opts = LiveOptions(
        speed=command.speed,
        lockstep=command.lockstep,
        method=method,
        seed=command.seed,
        out_dir=out_dir,
        zenoh_endpoint=ports.zenoh,
        zenoh_connect=command.zenoh_connect,
        **ports.mavlink,
        vehicle_links=command.vehicle_links,
        resume=command.resume,
        plan_budget_s=command.plan_budget_s if command.plan_budget_s > 0 else None,
        link_outages=command.link_outages,
        link_impairment=command.link_impairment,
        planner_cluster=planner_cluster,
    )
    return opts, ports.console


MethodOpt = Annotated[
    str | None,
    typer.Option(
        help=f"Planning method: {methods_help()}. Default: horizon; on a multi-target scenario "
        "proposed (horizon plans every track there too, not yet better)."
    ),
]


@app.command()
def run(
    config: ConfigArg,
    speed: SpeedOpt = 1.0,
    lockstep: Annotated[
        bool, typer.Option(help="The world waits at each slot for its plan.")
    ] = False,
    method: MethodOpt = None,
    seed: SeedOpt = None,
    out: Annotated[Path | None, typer.Option(help="Output folder (trace, plots).")] = None,
    zenoh_listen: Annotated[
        str | None,
        typer.Option(
            help="Zenoh endpoint the ground loop listens on (default tcp/127.0.0.1:7447, or "
            "tls/127.0.0.1:7447 with security.zenoh.tls, + --port-offset)."
        ),
    ] = None,
    mavlink_base_port: MavlinkBasePortOpt = None,
    mavlink_local_base_port: MavlinkLocalBasePortOpt = None,
    gcs_port: GcsPortOpt = None,
    gcs_local_base_port: GcsLocalBasePortOpt = None,
    port_offset: PortOffsetOpt = 0,
    plan_budget: PlanBudgetOpt = 1.0,
    inject_link_loss: InjectLinkLossOpt = None,
    impair_link: ImpairLinkOpt = None,
    console_address: LiveConsoleOpt = None,
    no_console: NoConsoleOpt = False,
    console_public: PublicOpt = False,
    planner_workers: PlannerWorkersOpt = 0,
    planner_scheduler: PlannerSchedulerOpt = None,
    planner_deadline: PlannerDeadlineOpt = None,
) -> None:
    """The live system in one process: simulated vehicles (MAVLink), target and sensing, MAVLink
    bridges and the ground loop, over real loopback UDP and Zenoh."""
    _live(
        LiveCommand(
            config,
            serve_only=False,
            speed=speed,
            lockstep=lockstep,
            method=method,
            seed=seed,
            out=out,
            zenoh_listen=zenoh_listen,
            mavlink_base_port=mavlink_base_port,
            mavlink_local_base_port=mavlink_local_base_port,
            gcs_port=gcs_port,
            gcs_local_base_port=gcs_local_base_port,
            port_offset=port_offset,
            plan_budget_s=plan_budget,
            link_outages=tuple(inject_link_loss or ()),
            link_impairment=tuple(impair_link or ()),
            serve_console=not no_console,
            console_address=console_address,
            console_public=console_public,
            planner_workers=planner_workers,
            planner_scheduler=planner_scheduler,
            planner_deadline_s=planner_deadline,
        )
    )


@app.command()
def serve(
    config: ConfigArg,
    method: MethodOpt = None,
    out: Annotated[Path | None, typer.Option(help="Output folder (trace, plots).")] = None,
    zenoh_listen: Annotated[
        str | None,
        typer.Option(
            help="Zenoh endpoint to listen on (default tcp/127.0.0.1:7447, or "
            "tls/127.0.0.1:7447 with security.zenoh.tls, + --port-offset)."
        ),
    ] = None,
    zenoh_connect: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoints to connect to.")
    ] = None,
    mavlink_base_port: ServeMavlinkBasePortOpt = None,
    port_offset: PortOffsetOpt = 0,
    resume: Annotated[
        bool,
        typer.Option(
            help="Continue the trace in --out after its last slot (refused when it is complete)."
        ),
    ] = False,
    plan_budget: PlanBudgetOpt = 1.0,
    vehicle_link: Annotated[
        list[str] | None,
        typer.Option(
            help="Vehicle M's link instead of UDP, as M=URL: M=serial:DEVICE[:BAUD] or "
            "M=udpin:127.0.0.1:PORT (repeatable; docs/service.md, 'Links')."
        ),
    ] = None,
    console_address: LiveConsoleOpt = None,
    no_console: NoConsoleOpt = False,
    console_public: PublicOpt = False,
    planner_workers: PlannerWorkersOpt = 0,
    planner_scheduler: PlannerSchedulerOpt = None,
    planner_deadline: PlannerDeadlineOpt = None,
) -> None:
    """The ground loop and the MAVLink bridges, for vehicles and sensing that run elsewhere
    (`isac-mission sim`, or real UAVs). The clock comes from the world over Zenoh."""
    _live(
        LiveCommand(
            config,
            serve_only=True,
            method=method,
            out=out,
            zenoh_listen=zenoh_listen,
            zenoh_connect=tuple(zenoh_connect or ()),
            mavlink_base_port=mavlink_base_port,
            port_offset=port_offset,
            resume=resume,
            plan_budget_s=plan_budget,
            vehicle_links=tuple(vehicle_link or ()),
            serve_console=not no_console,
            console_address=console_address,
            console_public=console_public,
            planner_workers=planner_workers,
            planner_scheduler=planner_scheduler,
            planner_deadline_s=planner_deadline,
        )
    )


@app.command("compile")
def compile_problems(
    config: ConfigArg,
    method: MethodOpt = None,
    live_settings: Annotated[
        bool,
        typer.Option(
            "--live-settings/--scenario-settings",
            help="Compile what `run` and `serve` plan with (the live settings), or what "
            "`simulate` plans with without --live-settings.",
        ),
    ] = True,
) -> None:
    """Compile the planner's IPOPT problems for CONFIG's fleet (and the smaller fleets `run`
    builds ahead: the fleet with one vehicle out, at least) into the cache ($ISAC_MISSION_NLP_CACHE, default ~/.cache/isac-mission/nlp), so that
    `run` and `serve` plan with compiled functions from their first slot (docs/performance.md,
    "Compiled problems"). Without it they compile in the background on their first run."""
    from isac_mission.config.live_settings import LIVE_SETTINGS
    from isac_mission.nlp_cache import CompiledNlpCache
    from isac_mission.planning.fleet import prepare_fleet
    from isac_mission.planning.kit import SolverKit
    from isac_mission.planning.registry import METHODS
    from isac_mission.planning.tracks import live_method
    from isac_mission.tracking.factory import keep_out_tracks

    s = load_or_exit(config)
    method = method or live_method(s)
    if method not in METHODS:
        err_console.print(f"--method: unknown {method!r}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    cache = CompiledNlpCache(compile="now")
    if cache.compiler is None:
        err_console.print(
            "no C compiler (gcc or cc on PATH, or $ISAC_MISSION_CC), or ISAC_MISSION_COMPILE=off: "
            "nothing compiled; the planner runs interpreted"
        )
        raise typer.Exit(2)
    planning = LIVE_SETTINGS.apply(s) if live_settings else s
    n_keep_out = keep_out_tracks(s)
    kit = SolverKit(planning, n_keep_out=n_keep_out, ipopt=cache)
    quiet_highs_banner()
    prepare_fleet(kit, method, n_keep_out)
    for line in cache.events:
        console.print(line, highlight=False)
    console.print(f"cache: {cache.directory}", highlight=False)
