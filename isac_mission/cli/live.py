"""`isac-mission run` (world, bridges and ground loop in one process), `serve` (bridges and
ground loop only) and `compile`: their options, live progress and Ctrl-C; the end of the
mission is printed by `cli/summary.py`."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

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
    from isac_mission.cli.mission import LiveOptions
    from isac_mission.config import Scenario
    from isac_mission.records.multi_target import MultiTargetSlot


def resolved_method(method: str | None, s: Scenario, out_dir: Path, resume: bool) -> str:
    """--method if given; else, resuming, the method of the one trace in out_dir
    (trace_<method>.jsonl: `serve --resume` continues what was flown), else the live default
    (`live_default_method`). ValueError when out_dir holds the traces of several methods."""
    from isac_mission.planning.registry import live_default_method

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
    return live_default_method(s.multi_target)


def resume_problem(s: Scenario, trace: Path) -> str | None:
    """Why `serve --resume` must not continue `trace` for `s` (None: it may): the trace is
    complete (its last slot is N: nothing left to fly), it does not read, or `s` is a
    multi-target mission (which cannot resume a trace yet). Reads the file, never writes it."""
    from isac_mission.errors import MessageError
    from isac_mission.records.progress import trace_progress

    if trace.exists():
        try:
            progress = trace_progress(trace)
        except MessageError as err:
            return f"cannot continue {trace}: {err}"
        if progress.last_slot >= s.N:
            return (
                f"the trace is complete: {progress.last_slot}/{s.N} slots in {trace}; nothing "
                "to resume (start a new mission without --resume, or in another --out)"
            )
    if s.multi_target:
        return (
            f"{s.mission_id} is a multi-target mission, which cannot resume a trace yet "
            "(docs/service.md, 'Several intruders'); start it without --resume"
        )
    return None


def _live(
    config: Path,
    *,
    serve_only: bool,
    speed: float,
    lockstep: bool,
    method: str | None,
    seed: int | None,
    out: Path | None,
    zenoh_listen: str | None,
    zenoh_connect: list[str],
    mavlink_base_port: int | None,
    mavlink_local_base_port: int | None,
    gcs_port: int | None,
    gcs_local_base_port: int | None,
    resume: bool,
    plan_budget: float,
    link_outages: list[str],
    link_impairment: list[str] | None = None,
    vehicle_links: list[str] | None = None,
    serve_console: bool = False,
    console_address: str | None = None,
    console_public: bool = False,
    port_offset: int = 0,
) -> None:
    """Shared body of `run` and `serve`: the console (when serve_console: on console_address,
    default 127.0.0.1:8080 + port_offset), live progress, summary, plots; exit 0 on
    SIGINT/SIGTERM. Bad input (an option, a port in use, a finished trace to resume) exits 2
    with one line, before anything is opened."""
    import logging

    from isac_mission.bus.session import check_listen_endpoints
    from isac_mission.cli.mission import LiveOptions
    from isac_mission.errors import PortInUseError
    from isac_mission.planning.registry import METHODS

    s = load_or_exit(config)
    try:
        ports = mission_ports(
            s,
            port_offset,
            zenoh=zenoh_listen,
            console=console_address,
            mavlink_base_port=mavlink_base_port,
            mavlink_local_base_port=mavlink_local_base_port,
            gcs_port=gcs_port,
            gcs_local_base_port=gcs_local_base_port,
        )
    except PortOptionError as err:
        err_console.print(str(err), highlight=False, markup=False)
        raise typer.Exit(2) from None
    out_dir = (
        out
        if out is not None
        else Path("out") / f"{'serve' if serve_only else 'run'}-{s.mission_id}"
    )
    try:
        method = resolved_method(method, s, out_dir, resume)
    except ValueError as err:
        err_console.print(f"--method: {err}", highlight=False)
        raise typer.Exit(2) from None
    if method not in METHODS:
        err_console.print(f"--method: unknown {method!r}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    if s.multi_target:
        from isac_mission.errors import ConfigError
        from isac_mission.planning.multi_target import check_multi_target_method

        try:
            check_multi_target_method(method)
        except ConfigError as err:
            err_console.print(f"--method: {err}", highlight=False)
            raise typer.Exit(2) from None
    if resume:
        problem = resume_problem(s, out_dir / f"trace_{method}.jsonl")
        if problem is not None:
            err_console.print(f"--resume: {problem}", highlight=False, markup=False)
            raise typer.Exit(2)
    try:
        check_listen_endpoints((ports.zenoh,))
    except PortInUseError as err:
        hint = ZENOH_PORT_HINT if zenoh_listen is None else ZENOH_LISTEN_HINT
        err_console.print(f"{err}; {hint}", highlight=False, markup=False)
        raise typer.Exit(2) from None
    quiet_highs_banner()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    if link_outages:
        from isac_mission.cli.embedded import check_link_outages

        try:
            check_link_outages(link_outages, s.M)
        except ValueError as err:
            err_console.print(f"--inject-link-loss: {err}", highlight=False)
            raise typer.Exit(2) from None
    if link_impairment:
        from isac_mission.cli.embedded import world_impairment
        from isac_mission.errors import ConfigError

        try:
            world_impairment(s, link_impairment)
        except ConfigError as err:
            err_console.print(f"[bold red]invalid option[/] {err}", highlight=False)
            raise typer.Exit(2) from None
    if vehicle_links:
        from isac_mission.mavwire.serial_link import parse_vehicle_links

        try:
            parse_vehicle_links(vehicle_links, s.M)
        except ValueError as err:
            err_console.print(f"--vehicle-link: {err}", highlight=False)
            raise typer.Exit(2) from None
    opts = LiveOptions(
        speed=speed,
        lockstep=lockstep,
        method=method,
        seed=seed,
        out_dir=out_dir,
        zenoh_endpoint=ports.zenoh,
        zenoh_connect=tuple(zenoh_connect),
        **ports.mavlink,
        vehicle_links=tuple(vehicle_links or ()),
        resume=resume,
        plan_budget_s=plan_budget if plan_budget > 0 else None,
        link_outages=tuple(link_outages),
        link_impairment=tuple(link_impairment or ()),
    )
    console_server = None
    if serve_console:
        from isac_mission.cli.mission import ground_endpoint
        from isac_mission.cli.view import start_live_console

        console_server = start_live_console(
            s, opts.method, ground_endpoint(s, opts), ports.console, public=console_public
        )
    code = 0
    try:
        _fly(s, opts, serve_only, out_dir)
    except typer.Exit as done:
        code = done.exit_code
        raise
    except BaseException:
        code = 1
        raise
    finally:
        if console_server is not None:
            console_server.stop()
        _wait_for_the_planners(code)


PLANNER_DRAIN_S = 60.0
"""How long `run` and `serve` wait at exit for a plan still being solved (wall seconds): a
timed-out plan's solve ends within IPOPT's iteration cap, seconds even for a large fleet."""


def _wait_for_the_planners(code: int) -> None:
    """No planner thread may be solving when the interpreter shuts down (a daemon thread in IPOPT
    then aborts the process: service/ground/planner_thread.py). Wait for them, bounded; past the
    bound, flush and leave at once with `code` (the trace and summary are already written)."""
    import os
    import sys

    from isac_mission.service.ground.planner_thread import drain_planner_threads, planner_threads

    if not planner_threads():
        return
    err_console.print("waiting for the planner to finish a solve before exiting")
    if drain_planner_threads(PLANNER_DRAIN_S):
        return
    err_console.print(
        f"a planner thread is still solving after {PLANNER_DRAIN_S:g} s; exiting without it"
    )
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def _fly(s: Scenario, opts: LiveOptions, serve_only: bool, out_dir: Path) -> None:
    """The mission with its live progress line, then the summary table and the plots."""
    import asyncio
    import signal

    import numpy as np
    from rich.live import Live

    from isac_mission.cli.mission import TAKING_OFF, LiveResult, run_serve
    from isac_mission.cli.stopping import StopRequests
    from isac_mission.cli.summary import print_summary
    from isac_mission.errors import IsacError, PortInUseError
    from isac_mission.service.ground.report import SlotEvent

    status = {"phase": "starting", "line": ""}
    last_slot = [0]
    took_off = [False]

    def render() -> Table:
        t = Table.grid(padding=(0, 2))
        t.add_row(f"[bold]{s.mission_id}[/] {opts.method}", status["phase"])
        if status["line"]:
            t.add_row("", status["line"])
        return t

    with Live(render(), console=console, refresh_per_second=8, transient=False) as live:

        def on_status(msg: str) -> None:
            status["phase"] = msg
            took_off[0] = took_off[0] or msg == TAKING_OFF
            live.update(render())

        def on_tracks(o: MultiTargetSlot, latency_s: float) -> None:
            last_slot[0] = o.slot
            confirmed = sum(t.confirmed for t in o.tracks)
            present = int(np.all(np.isfinite(o.truth), axis=1).sum())
            status["line"] = (
                f"slot {o.slot:3d}/{s.N}  targets {present}  tracks {confirmed} confirmed, "
                f"{len(o.tracks) - confirmed} tentative  planned for {o.planned_for or '-'}  "
                f"solve {o.plan.report.solve_s * 1e3:6.1f} ms  det->plan {latency_s * 1e3:6.1f} ms"
                f"  status {o.plan.report.status}"
            )
            live.update(render())

        def on_slot(ev: SlotEvent) -> None:
            r = ev.record
            last_slot[0] = r.slot
            err = "-" if ev.position_error_m is None else f"{ev.position_error_m:6.2f} m"
            links = " ".join(f"{m}:{v}" for m, v in sorted(ev.links.items())) or "-"
            status["line"] = (
                f"slot {r.slot:3d}/{s.N}  tr(PCRB) {r.pcrb_trace:8.4f}  position error {err}  "
                f"solve {r.solve_ms:6.1f} ms  det->plan {ev.latency_s * 1e3:6.1f} ms  "
                f"status {r.status}  links {links}"
            )
            live.update(render())

        requests = StopRequests(s.H, opts.speed, embedded=not serve_only)

        async def main_task() -> object:
            stop, leave = asyncio.Event(), asyncio.Event()
            loop = asyncio.get_running_loop()

            def on_signal(name: str) -> None:
                action, line = requests.on_signal(name, last_slot[0], s.N, took_off[0])
                live.console.print(line, highlight=False)
                if action == "stop":
                    stop.set()
                elif action == "leave":
                    leave.set()

            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, on_signal, sig.name)
            try:
                if serve_only:
                    return await run_serve(s, opts, stop, on_slot, on_status, on_tracks, leave)
                from isac_mission.cli.embedded import run_embedded

                return await run_embedded(s, opts, stop, on_slot, on_status, on_tracks, leave)
            finally:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.remove_signal_handler(sig)

        try:
            result = asyncio.run(main_task())
        except PortInUseError as err:  # taken since _live's check: as busy as it was then
            live.stop()
            err_console.print(f"{err}; {ZENOH_PORT_HINT}", highlight=False, markup=False)
            raise typer.Exit(2) from None
        except IsacError as err:
            err_console.print(f"[bold red]mission failed:[/] {err}")
            raise typer.Exit(1) from None
    console.print()
    assert isinstance(result, LiveResult)
    print_summary(s, opts, result, out_dir, last_slot[0])


MethodOpt = Annotated[
    str | None,
    typer.Option(
        help=f"Planning method: {methods_help()}. Default: horizon; on a multi-target scenario "
        "proposed (horizon plans one target)."
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
) -> None:
    """The live system in one process: simulated vehicles (MAVLink), target and sensing, MAVLink
    bridges and the ground loop, over real loopback UDP and Zenoh."""
    _live(
        config,
        serve_only=False,
        speed=speed,
        lockstep=lockstep,
        method=method,
        seed=seed,
        out=out,
        zenoh_listen=zenoh_listen,
        zenoh_connect=[],
        mavlink_base_port=mavlink_base_port,
        mavlink_local_base_port=mavlink_local_base_port,
        gcs_port=gcs_port,
        gcs_local_base_port=gcs_local_base_port,
        resume=False,
        plan_budget=plan_budget,
        link_outages=inject_link_loss or [],
        link_impairment=impair_link or [],
        serve_console=not no_console,
        console_address=console_address,
        console_public=console_public,
        port_offset=port_offset,
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
) -> None:
    """The ground loop and the MAVLink bridges, for vehicles and sensing that run elsewhere
    (`isac-mission sim`, or real UAVs). The clock comes from the world over Zenoh."""
    _live(
        config,
        serve_only=True,
        speed=1.0,
        lockstep=False,
        method=method,
        seed=None,
        out=out,
        zenoh_listen=zenoh_listen,
        zenoh_connect=zenoh_connect or [],
        mavlink_base_port=mavlink_base_port,
        mavlink_local_base_port=None,
        gcs_port=None,
        gcs_local_base_port=None,
        resume=resume,
        plan_budget=plan_budget,
        link_outages=[],
        vehicle_links=vehicle_link,
        serve_console=not no_console,
        console_address=console_address,
        console_public=console_public,
        port_offset=port_offset,
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
    from isac_mission.planning.multi_target import KEEP_OUT_CAPACITY
    from isac_mission.planning.registry import METHODS, live_default_method
    from isac_mission.planning.slot import SolverKit

    s = load_or_exit(config)
    method = method or live_default_method(s.multi_target)
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
    n_keep_out = KEEP_OUT_CAPACITY if s.multi_target else 0
    kit = SolverKit(planning, n_keep_out=n_keep_out, ipopt=cache)
    quiet_highs_banner()
    prepare_fleet(kit, method, n_keep_out)
    for line in cache.events:
        console.print(line, highlight=False)
    console.print(f"cache: {cache.directory}", highlight=False)
