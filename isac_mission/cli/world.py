"""`isac-mission sim`: the world alone (simulated vehicles, target, sensing, clock) on the bus."""

from __future__ import annotations

from typing import Annotated

import typer

from isac_mission.cli.app import ConfigArg, InjectLinkLossOpt, app, err_console, load_or_exit
from isac_mission.errors import ConfigError


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

    from isac_mission.bus.security import default_endpoint, secured_settings
    from sim.world import run_world
    from sim.world_options import WorldOptions, parse_outages

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
