"""The `isac-mission` command line: simulate, check-config (and the live commands)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, cast

import typer
from rich.console import Console
from rich.table import Table

from isac_mission.config import Scenario, load_scenario
from isac_mission.errors import ConfigError
from isac_mission.planning.slot import METHODS, Method
from isac_mission.quiet import quiet_highs_banner

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
        str, typer.Option(help="Comma-separated: proposed, sd, aba, crb, comm.")
    ] = "proposed,sd,aba,crb",
    workers: Annotated[int, typer.Option(min=1, help="Worker processes.")] = 2,
    plots: Annotated[bool, typer.Option(help="Write the Fig. 2 / Fig. 3 style PNGs.")] = True,
) -> None:
    """Offline closed loop (Section II-C) for every method, Monte Carlo with common random numbers."""
    from isac_mission.experiment.report import simulate_report

    s = load_or_exit(config)
    chosen = [m.strip() for m in methods.split(",") if m.strip()]
    unknown = sorted(set(chosen) - set(METHODS))
    if unknown or not chosen:
        err_console.print(f"--methods: unknown {unknown}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    quiet_highs_banner()
    out_dir = out if out is not None else Path("out") / f"simulate-{s.mission_id}"
    simulate_report(
        s,
        [cast(Method, m) for m in chosen],
        runs=runs,
        seed=s.seed if seed is None else seed,
        out_dir=out_dir,
        workers=workers,
        plots=plots,
        console=console,
    )


@app.command()
def sweep(
    config: ConfigArg,
    grid: Annotated[
        Path,
        typer.Option(
            help="Grid YAML: dotted config paths -> lists of values (+ methods, "
            "runs, seed, slots); see config/grids/example.yaml."
        ),
    ],
    out: Annotated[
        Path | None, typer.Option(help="Output folder (sweep.csv, runs.csv, plots).")
    ] = None,
    workers: Annotated[
        int, typer.Option(min=0, help="Local Dask worker processes (0: serial, no Dask).")
    ] = 2,
    serial: Annotated[bool, typer.Option(help="Run in this process without Dask.")] = False,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Existing Dask scheduler, e.g. tcp://HOST:8786 (default: a local "
            "cluster on 127.0.0.1)."
        ),
    ] = None,
    seed: Annotated[
        int | None, typer.Option(help="Base seed (default: the grid's, else the config's).")
    ] = None,
    plots: Annotated[bool, typer.Option(help="Write RMSE-vs-parameter PNGs.")] = True,
) -> None:
    """Monte Carlo over a parameter grid, on Dask (grid point x method x run, seed = seed + run)."""
    from isac_mission.experiment import sweep as sw
    from isac_mission.experiment.report import mission_progress

    try:
        plan = sw.plan_sweep(config, grid, seed)
    except ConfigError as err:
        err_console.print(f"[bold red]invalid sweep[/]\n{err}", highlight=False)
        raise typer.Exit(2) from None
    use_dask = not serial and (workers > 0 or scheduler is not None)
    where = (
        f"scheduler {scheduler}"
        if scheduler and use_dask
        else (f"local cluster of {workers} workers on 127.0.0.1" if use_dask else "serial")
    )
    g = plan.grid
    console.print(
        f"[bold]{plan.mission_id}[/]: {len(plan.points)} grid points x {len(g.methods)} methods x "
        f"{g.runs} runs = {len(plan.tasks)} missions, seeds {plan.seed}..{plan.seed + g.runs - 1}, "
        f"{where}",
        highlight=False,
    )
    quiet_highs_banner()
    with mission_progress(console) as bar:
        task = bar.add_task("missions", total=len(plan.tasks))

        def done(_row: sw.TaskRow) -> None:
            bar.advance(task)

        if use_dask:
            from isac_mission.experiment.sweep_dask import dask_client, run_dask

            with dask_client(scheduler, workers) as client:
                rows = run_dask(client, plan.tasks, done)
        else:
            rows = sw.run_serial(plan.tasks, done)
    summaries = sw.aggregate(rows, plan.points)
    console.print(
        sw.sweep_table(
            summaries, g.paths, f"{plan.mission_id}: {g.runs} runs per point (95% t-intervals)"
        )
    )
    out_dir = out if out is not None else Path("out") / f"sweep-{plan.mission_id}"
    csv_path = sw.write_csv(summaries, g.paths, out_dir / "sweep.csv")
    sw.write_rows_csv(rows, out_dir / "runs.csv")
    console.print(f"results: {csv_path}  per-run rows: {out_dir / 'runs.csv'}")
    if plots:
        written = sw.plot_sweep(summaries, g, out_dir)
        console.print("plots: " + ", ".join(str(p) for p in written))


@app.command("sim")
def sim(
    config: ConfigArg,
    speed: Annotated[
        float, typer.Option(help="Simulation seconds per wall second (inf: as fast as possible).")
    ] = 1.0,
    lockstep: Annotated[
        bool, typer.Option(help="Hold the clock at each slot boundary until the next plan.")
    ] = False,
    lockstep_timeout: Annotated[
        float, typer.Option(help="Wall seconds to wait for a plan in lockstep.")
    ] = 30.0,
    seed: Annotated[int | None, typer.Option(help="Noise seed (default: the config's).")] = None,
    zenoh_listen: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoint to listen on (repeatable).")
    ] = None,
    zenoh_connect: Annotated[
        list[str] | None,
        typer.Option(
            help="Zenoh endpoint to connect to (repeatable; default tcp/127.0.0.1:7447, or "
            "tls/127.0.0.1:7447 with security.zenoh.tls)."
        ),
    ] = None,
    zenoh_mode: Annotated[str, typer.Option(help="Zenoh mode: peer, client or router.")] = "peer",
    mavlink_base_port: Annotated[
        int, typer.Option(help="Vehicle m sends offboard MAVLink to 127.0.0.1:(P + m).")
    ] = 14540,
    gcs_base_port: Annotated[
        int, typer.Option(help="Vehicle m sends GCS MAVLink to 127.0.0.1:(P + m).")
    ] = 14550,
    start: Annotated[
        str,
        typer.Option(help="Slot 0 begins: immediate, or offboard (all vehicles up in OFFBOARD)."),
    ] = "immediate",
    inject_link_loss: InjectLinkLossOpt = None,
) -> None:
    """The world alone (vehicles, target, sensing, clock) until SIGINT or SIGTERM."""
    import asyncio
    import logging
    import signal

    from isac_mission.service.bus_security import default_endpoint, secured_settings
    from sim.world import WorldOptions, parse_outages, run_world

    s = load_or_exit(config)
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    listen = tuple(zenoh_listen or ())
    connect = tuple(zenoh_connect or ()) or (
        () if listen else (default_endpoint(s.security.zenoh),)
    )
    try:
        # Security on: logs in as the world role (README, "Security").
        bus = secured_settings(
            s.security.zenoh,
            s.mission_id,
            "world",
            mode=zenoh_mode,  # type: ignore[arg-type]
            listen=listen,
            connect=connect,
        )
        options = WorldOptions(
            speed=speed,
            lockstep=lockstep,
            lockstep_timeout_s=lockstep_timeout,
            seed=seed,
            bus=bus,
            mavlink_base_port=mavlink_base_port,
            gcs_base_port=gcs_base_port,
            start=start,  # type: ignore[arg-type]
            link_outages=parse_outages(inject_link_loss or [], s.M),
        )
    except (ConfigError, ValueError) as err:
        err_console.print(f"[bold red]invalid option[/] {err}", highlight=False)
        raise typer.Exit(2) from None

    async def _main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        try:
            stats = await run_world(s, options, stop)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)
        err_console.print(
            f"world stopped: {stats.slots} slots, t = {stats.sim_time_s:.1f} s, "
            f"{stats.plans_received} plans ({stats.plans_rejected} rejected)",
            highlight=False,
        )

    try:
        asyncio.run(_main())
    except ConfigError as err:
        err_console.print(f"[bold red]cannot start the world[/] {err}", highlight=False)
        raise typer.Exit(1) from None


def _live(
    config: Path,
    *,
    serve_only: bool,
    speed: float,
    lockstep: bool,
    method: str,
    seed: int | None,
    out: Path | None,
    zenoh_listen: str | None,
    zenoh_connect: list[str],
    mavlink_base_port: int,
    gcs_base_port: int,
    resume: bool,
    plan_budget: float,
    link_outages: list[str],
) -> None:
    """Shared body of `run` and `serve`: live progress, summary, plots; exit 0 on SIGINT/SIGTERM."""
    import asyncio
    import logging
    import signal

    from rich.live import Live

    from isac_mission.errors import IsacError
    from isac_mission.service.ground.report import SlotEvent
    from isac_mission.service.live import LiveOptions, run_embedded, run_serve, summarize_live

    s = load_or_exit(config)
    if method not in METHODS:
        err_console.print(f"--method: unknown {method!r}; choose from {', '.join(METHODS)}")
        raise typer.Exit(2)
    quiet_highs_banner()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    out_dir = (
        out
        if out is not None
        else Path("out") / f"{'serve' if serve_only else 'run'}-{s.mission_id}"
    )
    if link_outages:
        from sim.world import parse_outages

        try:
            parse_outages(link_outages, s.M)
        except ValueError as err:
            err_console.print(f"--inject-link-loss: {err}", highlight=False)
            raise typer.Exit(2) from None
    opts = LiveOptions(
        speed=speed,
        lockstep=lockstep,
        method=method,
        seed=seed,
        out_dir=out_dir,
        zenoh_endpoint=zenoh_listen,
        zenoh_connect=tuple(zenoh_connect),
        mavlink_base_port=mavlink_base_port,
        gcs_base_port=gcs_base_port,
        resume=resume,
        plan_budget_s=plan_budget if plan_budget > 0 else None,
        link_outages=tuple(link_outages),
    )
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
                runner = run_serve if serve_only else run_embedded
                return await runner(s, opts, stop, on_slot, on_status)
            finally:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.remove_signal_handler(sig)

        try:
            result = asyncio.run(main_task())
        except IsacError as err:
            err_console.print(f"[bold red]mission failed:[/] {err}")
            raise typer.Exit(1) from None
    console.print()
    from isac_mission.service.live import LiveResult

    assert isinstance(result, LiveResult)
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
        )
        from isac_mission.records import read_trace

        trace = read_trace(result.trace_path)
        written = [
            plot_trajectories(trace, out_dir / "fig2a_trajectories.png"),
            plot_bandwidth(trace, out_dir / "fig2b_bandwidth.png"),
            plot_performance({opts.method: [trace]}, out_dir / "fig3_performance.png"),
        ]
        console.print("plots: " + ", ".join(str(p) for p in written))
    console.print(f"trace: {result.trace_path}")


MethodOpt = Annotated[str, typer.Option(help="Planning method: proposed, sd, aba, crb, comm.")]
SpeedOpt = Annotated[float, typer.Option(help="Simulation seconds per wall second.")]


@app.command()
def run(
    config: ConfigArg,
    speed: SpeedOpt = 1.0,
    lockstep: Annotated[
        bool, typer.Option(help="The world waits at each slot for its plan.")
    ] = False,
    method: MethodOpt = "proposed",
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
    mavlink_base_port: Annotated[
        int, typer.Option(help="Vehicle m's offboard port: base + m.")
    ] = 14540,
    gcs_base_port: Annotated[
        int, typer.Option(help="Vehicle m's ground-station port: base + m.")
    ] = 14550,
    plan_budget: PlanBudgetOpt = 1.0,
    inject_link_loss: InjectLinkLossOpt = None,
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
        gcs_base_port=gcs_base_port,
        resume=False,
        plan_budget=plan_budget,
        link_outages=inject_link_loss or [],
    )


@app.command()
def serve(
    config: ConfigArg,
    method: MethodOpt = "proposed",
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
        int, typer.Option(help="Vehicle m's offboard port: base + m.")
    ] = 14540,
    resume: Annotated[
        bool, typer.Option(help="Continue the trace in --out after its last slot.")
    ] = False,
    plan_budget: PlanBudgetOpt = 1.0,
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
        gcs_base_port=14550,
        resume=resume,
        plan_budget=plan_budget,
        link_outages=[],
    )


@app.command("gen-certs")
def gen_certs(
    out_dir: Annotated[Path, typer.Argument(help="Folder for ca.pem, server.pem and their keys.")],
    days: Annotated[int, typer.Option(min=1, help="Validity in days.")] = 365,
    force: Annotated[bool, typer.Option(help="Replace existing files.")] = False,
) -> None:
    """A local CA and a TLS certificate for 127.0.0.1 / localhost (needs the openssl command),
    for security.zenoh.tls (README, "Security")."""
    from isac_mission.service.certs import generate_certs

    try:
        files = generate_certs(out_dir, days=days, force=force)
    except ConfigError as err:
        err_console.print(f"[bold red]{err}[/]", highlight=False)
        raise typer.Exit(1) from None
    console.print(
        "security.zenoh.tls:\n"
        f"  ca_file: {files.ca_file}\n  cert_file: {files.cert_file}\n  key_file: {files.key_file}\n"
        f"(keep {files.ca_key_file} elsewhere: it signs certificates)",
        highlight=False,
    )


@app.command("gen-users")
def gen_users(
    users_file: Annotated[Path, typer.Argument(help="The users file to write (mode 0600).")],
    config: Annotated[
        Path | None, typer.Option(help="Take the users from this scenario's security.zenoh.roles.")
    ] = None,
    force: Annotated[bool, typer.Option(help="Replace an existing file.")] = False,
) -> None:
    """A Zenoh users file (`user:password` lines, random passwords) for security.zenoh.users_file;
    by default the users ground, world, operator and observer. Prints the users, never the
    passwords."""
    from isac_mission.config import ZenohSecurityConfig
    from isac_mission.service.certs import generate_users_file

    cfg = load_or_exit(config).security.zenoh if config is not None else ZenohSecurityConfig()
    try:
        names = generate_users_file(
            users_file, (u for role in cfg.roles.values() for u in role.users), force=force
        )
    except ConfigError as err:
        err_console.print(f"[bold red]{err}[/]", highlight=False)
        raise typer.Exit(1) from None
    console.print(f"{users_file}: users {', '.join(names)}", highlight=False)


def main() -> None:
    """Console-script entry point."""
    sys.exit(app())


if __name__ == "__main__":
    main()
