"""`isac-mission run` (world, bridges and ground loop in one process) and `serve` (bridges and
ground loop only): live progress, the end-of-run summary table and the plots."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.table import Table

from isac_mission.cli.app import (
    ConfigArg,
    ConsoleOpt,
    ImpairLinkOpt,
    InjectLinkLossOpt,
    NoConsoleOpt,
    PlanBudgetOpt,
    PublicOpt,
    app,
    console,
    err_console,
    load_or_exit,
)
from isac_mission.cli.ports import (
    GcsLocalBasePortOpt,
    GcsPortOpt,
    MavlinkBasePortOpt,
    MavlinkLocalBasePortOpt,
    port_options,
)
from isac_mission.planning.registry import methods_help
from isac_mission.quiet import quiet_highs_banner

if TYPE_CHECKING:
    from isac_mission.cli.mission import LiveOptions, LiveResult
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
    console_address: str | None = None,
    console_public: bool = False,
) -> None:
    """Shared body of `run` and `serve`: the console (unless console_address is None), live
    progress, summary, plots; exit 0 on SIGINT/SIGTERM."""
    import logging

    from isac_mission.cli.mission import LiveOptions
    from isac_mission.planning.registry import METHODS

    s = load_or_exit(config)
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
        zenoh_endpoint=zenoh_listen,
        zenoh_connect=tuple(zenoh_connect),
        **port_options(
            s, mavlink_base_port, mavlink_local_base_port, gcs_port, gcs_local_base_port
        ),
        vehicle_links=tuple(vehicle_links or ()),
        resume=resume,
        plan_budget_s=plan_budget if plan_budget > 0 else None,
        link_outages=tuple(link_outages),
        link_impairment=tuple(link_impairment or ()),
    )
    console_server = None
    if console_address is not None:
        from isac_mission.cli.mission import ground_endpoint
        from isac_mission.cli.view import start_live_console

        console_server = start_live_console(
            s, opts.method, ground_endpoint(s, opts), console_address, public=console_public
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

    from isac_mission.cli.mission import LiveResult, run_serve, summarize_live
    from isac_mission.errors import IsacError
    from isac_mission.service.ground.report import SlotEvent

    status = {"phase": "starting", "line": ""}

    def render() -> Table:
        t = Table.grid(padding=(0, 2))
        t.add_row(f"[bold]{s.mission_id}[/] {opts.method}", status["phase"])
        if status["line"]:
            t.add_row("", status["line"])
        return t

    with Live(render(), console=console, refresh_per_second=8, transient=False) as live:

        def on_status(msg: str) -> None:
            status["phase"] = msg
            live.update(render())

        def on_tracks(o: MultiTargetSlot, latency_s: float) -> None:
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
            err = "-" if ev.position_error_m is None else f"{ev.position_error_m:6.2f} m"
            links = " ".join(f"{m}:{v}" for m, v in sorted(ev.links.items())) or "-"
            status["line"] = (
                f"slot {r.slot:3d}/{s.N}  tr(PCRB) {r.pcrb_trace:8.4f}  position error {err}  "
                f"solve {r.solve_ms:6.1f} ms  det->plan {ev.latency_s * 1e3:6.1f} ms  "
                f"status {r.status}  links {links}"
            )
            live.update(render())

        async def main_task() -> object:
            stop = asyncio.Event()
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, stop.set)
            try:
                if serve_only:
                    return await run_serve(s, opts, stop, on_slot, on_status, on_tracks)
                from isac_mission.cli.embedded import run_embedded

                return await run_embedded(s, opts, stop, on_slot, on_status, on_tracks)
            finally:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.remove_signal_handler(sig)

        try:
            result = asyncio.run(main_task())
        except IsacError as err:
            err_console.print(f"[bold red]mission failed:[/] {err}")
            raise typer.Exit(1) from None
    console.print()
    assert isinstance(result, LiveResult)
    ahead = f"built for {s.M} vehicles and, ahead, for {result.sizes_built_ahead}"
    for line in [ahead, *result.planner_problems]:
        console.print(f"planner problems: {line}", highlight=False)
    if s.multi_target:
        _multi_target_summary(s, opts, result, out_dir)
        return
    summary = summarize_live(result)
    table = Table(title=f"{s.mission_id}: live mission summary ({opts.method})")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for name, value in (
        ("slots completed", f"{summary.slots}/{s.N}"),
        ("location RMSE", f"{summary.loc_rmse:.3f} m"),
        ("velocity RMSE", f"{summary.vel_rmse:.4f} m/s"),
        ("mean tr(PCRB)", f"{summary.pcrb_mean:.4f}"),
        (
            "plan solve time median / p95",
            f"{summary.solve_median_ms:.1f} / {summary.solve_p95_ms:.1f} ms",
        ),
        (
            "detection-to-plan median / p99",
            f"{summary.latency_median_ms:.1f} / {summary.latency_p99_ms:.1f} ms",
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
        from isac_mission.experiment.plots import (
            plot_bandwidth,
            plot_performance,
            plot_trajectories,
            save_png,
        )
        from isac_mission.records import read_trace

        trace = read_trace(result.trace_path)
        written = [
            save_png(plot_trajectories(trace), out_dir / "fig2a_trajectories.png"),
            save_png(plot_bandwidth(trace), out_dir / "fig2b_bandwidth.png"),
            save_png(plot_performance({opts.method: [trace]}), out_dir / "fig3_performance.png"),
        ]
        console.print("plots: " + ", ".join(str(p) for p in written))
    console.print(f"trace: {result.trace_path}")


def _multi_target_summary(
    s: Scenario, opts: LiveOptions, result: LiveResult, out_dir: Path
) -> None:
    """A multi-target mission's tracking tables (as `simulate` prints them, over this one run),
    its counters, and its picture."""
    from isac_mission.experiment.multi_target_metrics import (
        run_figures,
        run_of_slots,
        summarize_tracking,
    )
    from isac_mission.experiment.multi_target_plots import save_tracks_png
    from isac_mission.experiment.multi_target_report import target_table, tracking_table

    slots = result.multi_target_slots
    console.print(f"slots completed: {len(slots)}/{s.N}")
    if slots:
        seed = s.seed if opts.seed is None else opts.seed
        figures = run_figures(
            run_of_slots(opts.method, seed, slots), s.multi_tracker.gospa_cutoff_m
        )
        summaries = {opts.method: summarize_tracking([figures])}
        console.print(tracking_table(s, summaries, f"{s.mission_id}: live mission, tracking"))
        console.print(target_table(s, summaries))
    counters = Table(title="counters")
    counters.add_column("counter")
    counters.add_column("value", justify="right")
    for k, v in (*sorted(result.report.counters.items()), *result.fleet_counters.items()):
        counters.add_row(k, str(v))
    console.print(counters)
    if slots:
        png = save_tracks_png(result.trace_path, out_dir / f"tracks_{opts.method}.png")
        console.print(f"plot: {png}")
    console.print(f"trace: {result.trace_path}")


MethodOpt = Annotated[
    str | None,
    typer.Option(
        help=f"Planning method: {methods_help()}. Default: horizon; on a multi-target scenario "
        "proposed (horizon plans one target)."
    ),
]
SpeedOpt = Annotated[float, typer.Option(help="Simulation seconds per wall second.")]


@app.command()
def run(
    config: ConfigArg,
    speed: SpeedOpt = 1.0,
    lockstep: Annotated[
        bool, typer.Option(help="The world waits at each slot for its plan.")
    ] = False,
    method: MethodOpt = None,
    seed: Annotated[
        int | None, typer.Option(help="World noise seed (default: the config's).")
    ] = None,
    out: Annotated[Path | None, typer.Option(help="Output folder (trace, plots).")] = None,
    zenoh_listen: Annotated[
        str | None,
        typer.Option(
            help="Zenoh endpoint the ground loop listens on (default tcp/127.0.0.1:7447, or "
            "tls/127.0.0.1:7447 with security.zenoh.tls)."
        ),
    ] = None,
    mavlink_base_port: MavlinkBasePortOpt = None,
    mavlink_local_base_port: MavlinkLocalBasePortOpt = None,
    gcs_port: GcsPortOpt = None,
    gcs_local_base_port: GcsLocalBasePortOpt = None,
    plan_budget: PlanBudgetOpt = 1.0,
    inject_link_loss: InjectLinkLossOpt = None,
    impair_link: ImpairLinkOpt = None,
    console_address: ConsoleOpt = "127.0.0.1:8080",
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
        console_address=None if no_console else console_address,
        console_public=console_public,
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
            "tls/127.0.0.1:7447 with security.zenoh.tls)."
        ),
    ] = None,
    zenoh_connect: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoints to connect to.")
    ] = None,
    mavlink_base_port: Annotated[
        int | None,
        typer.Option(
            help="The bridge of vehicle m listens on 127.0.0.1:(P + m) (default: the scenario's "
            "links.offboard_base_port, PX4 SITL's offboard ports 14540)."
        ),
    ] = None,
    resume: Annotated[
        bool, typer.Option(help="Continue the trace in --out after its last slot.")
    ] = False,
    plan_budget: PlanBudgetOpt = 1.0,
    vehicle_link: Annotated[
        list[str] | None,
        typer.Option(
            help="Vehicle M's link instead of UDP, as M=URL: M=serial:DEVICE[:BAUD] or "
            "M=udpin:127.0.0.1:PORT (repeatable; docs/service.md, 'Links')."
        ),
    ] = None,
    console_address: ConsoleOpt = "127.0.0.1:8080",
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
        console_address=None if no_console else console_address,
        console_public=console_public,
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
