"""The simulator inside an `isac-mission` process: the only CLI module that imports `sim`.

- `isac-mission sim`: the world alone (simulated vehicles, target, sensing, clock) on the bus;
- embedded mode (`isac-mission run`, `embedded_world`): the world beside the bridges and the ground
  loop that `isac_mission.service.assembly` puts together, over loopback UDP MAVLink and a Zenoh
  session the ground side listens on. This is the only module that imports both `sim` and the
  service.

`sim` and the service are imported inside the functions, so registering the commands (every
`isac-mission` start) loads neither.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Annotated

import typer

from isac_mission.cli.app import (
    ConfigArg,
    ImpairLinkOpt,
    InjectLinkLossOpt,
    SpeedOpt,
    app,
    err_console,
    load_or_exit,
    number_check,
)
from isac_mission.cli.ports import (
    ZENOH_LISTEN_HINT,
    GcsLocalBasePortOpt,
    GcsPortOpt,
    MavlinkBasePortOpt,
    MavlinkLocalBasePortOpt,
    PortOffsetOpt,
    PortOptionError,
    port_options,
    zenoh_endpoint,
)
from isac_mission.config import ImpairmentConfig, apply_impairment_flags
from isac_mission.errors import ConfigError

if TYPE_CHECKING:
    from isac_mission.config import Scenario
    from isac_mission.records.tracks import TracksSlot
    from isac_mission.service.assembly import LiveOptions, WorldBeside
    from isac_mission.service.ground.report import SlotEvent
    from isac_mission.service.mission_result import LiveResult


@app.command("sim")
def sim(
    config: ConfigArg,
    speed: SpeedOpt = 1.0,
    lockstep: Annotated[
        bool, typer.Option(help="Hold the clock at each slot boundary until the next plan.")
    ] = False,
    lockstep_timeout: Annotated[
        float,
        typer.Option(
            callback=number_check(above=0.0),
            help="Wall seconds to wait for a plan in lockstep (> 0).",
        ),
    ] = 30.0,
    seed: Annotated[
        int | None, typer.Option(min=0, help="Noise seed (default: the config's).")
    ] = None,
    zenoh_listen: Annotated[
        list[str] | None, typer.Option(help="Zenoh endpoint to listen on (repeatable).")
    ] = None,
    zenoh_connect: Annotated[
        list[str] | None,
        typer.Option(
            help="Zenoh endpoint to connect to (repeatable; default tcp/127.0.0.1:7447, or "
            "tls/127.0.0.1:7447 with security.zenoh.tls, + --port-offset; none when "
            "--zenoh-listen is given)."
        ),
    ] = None,
    zenoh_mode: Annotated[str, typer.Option(help="Zenoh mode: peer, client or router.")] = "peer",
    mavlink_base_port: MavlinkBasePortOpt = None,
    mavlink_local_base_port: MavlinkLocalBasePortOpt = None,
    gcs_port: GcsPortOpt = None,
    gcs_local_base_port: GcsLocalBasePortOpt = None,
    port_offset: PortOffsetOpt = 0,
    start: Annotated[
        str,
        typer.Option(help="Slot 0 begins: immediate, or offboard (all vehicles up in OFFBOARD)."),
    ] = "immediate",
    inject_link_loss: InjectLinkLossOpt = None,
    impair_link: ImpairLinkOpt = None,
    serial_link: Annotated[
        list[str] | None,
        typer.Option(
            help="Vehicle M also speaks MAVLink on a serial device, as M=DEVICE[:BAUD] "
            "(e.g. 0=/dev/ttyUSB0:57600; repeatable; docs/deployment.md, 'Links as deployed')."
        ),
    ] = None,
) -> None:
    """The world alone (vehicles, target, sensing, clock) until SIGINT or SIGTERM."""
    import logging
    import signal

    from isac_mission.bus.security import secured_settings
    from isac_mission.bus.session import check_listen_endpoints
    from isac_mission.errors import PortInUseError
    from sim.world import run_world
    from sim.world_options import WorldOptions, parse_outages, parse_serial_links

    s = load_or_exit(config)
    listen = tuple(zenoh_listen or ())
    try:
        connect = tuple(zenoh_connect or ()) or (
            () if listen else (zenoh_endpoint(s, port_offset),)
        )
        ports = port_options(
            s,
            mavlink_base_port,
            mavlink_local_base_port,
            gcs_port,
            gcs_local_base_port,
            offset=port_offset,
        )
    except PortOptionError as err:
        err_console.print(str(err), highlight=False, markup=False)
        raise typer.Exit(2) from None
    try:
        # Security on: logs in as the world role (docs/deployment.md, "Security").
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
            **ports,
            start=start,  # type: ignore[arg-type]
            link_outages=parse_outages(inject_link_loss or [], s.M),
            impairment=world_impairment(s, impair_link or []),
            serial_links=parse_serial_links(serial_link or [], s.M),
        )
        check_listen_endpoints(listen)
    except PortInUseError as err:
        err_console.print(f"{err}; {ZENOH_LISTEN_HINT}", highlight=False, markup=False)
        raise typer.Exit(2) from None
    except (ConfigError, ValueError) as err:
        err_console.print(f"[bold red]invalid option[/] {err}", highlight=False)
        raise typer.Exit(2) from None
    if not logging.getLogger().handlers:
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")

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
    except PortInUseError as err:  # taken since the check above (sim listens where told)
        err_console.print(f"{err}; {ZENOH_LISTEN_HINT}", highlight=False, markup=False)
        raise typer.Exit(2) from None
    except (ConfigError, OSError) as err:  # OSError: a port taken, a serial device missing
        err_console.print(f"[bold red]cannot start the world[/] {err}", highlight=False)
        raise typer.Exit(1) from None


def world_impairment(s: Scenario, specs: Sequence[str]) -> ImpairmentConfig | None:
    """The scenario's impairment with the `--impair-link` specs applied (None: no specs, the
    scenario's own); ConfigError naming the spec and the field, or a vehicle the fleet lacks."""
    if not specs:
        return None
    out = apply_impairment_flags(s.impairment, list(specs))
    bad = sorted(m for m in out.vehicles if m >= s.M)
    if bad:
        raise ConfigError(f"--impair-link: no vehicle {bad[0]} (M = {s.M})")
    return out


def check_link_outages(specs: Sequence[str], n_uavs: int) -> None:
    """Validate `--inject-link-loss` specs (`VEHICLE:START_S:DURATION_S`); ValueError if bad."""
    from sim.world_options import parse_outages

    parse_outages(specs, n_uavs)


def embedded_world(s: Scenario, opts: LiveOptions) -> WorldBeside:
    """The simulated world of `run`, beside the service: it connects to the ground's endpoint
    (logging in as the world role), flies `simulate`'s truth for the seed, and the tracker
    starts where `simulate`'s does."""
    from isac_mission.bus.security import secured_settings
    from isac_mission.service.assembly import WorldBeside, ground_endpoint
    from isac_mission.tracking.factory import initial_errors
    from sim.world import run_world
    from sim.world_options import WorldOptions, parse_outages

    # The world logs in as the world role, with its password from the hub's own users file.
    world_bus = secured_settings(
        s.security.zenoh,
        s.mission_id,
        "world",
        connect=(ground_endpoint(s, opts),),
        login_from_users_file=True,
    )
    # The offline twin: the world flies `simulate`'s targets and reports for this seed
    # (sim/world_assembly.py), and each known target's track starts where `simulate`'s does.
    seed = s.seed if opts.seed is None else opts.seed
    world_opts = WorldOptions(
        speed=opts.speed,
        lockstep=opts.lockstep,
        seed=seed,
        initial_error=False,
        bus=world_bus,
        mavlink_base_port=opts.mavlink_base_port,
        mavlink_local_base_port=opts.mavlink_local_base_port,
        gcs_port=opts.gcs_port,
        gcs_local_base_port=opts.gcs_local_base_port,
        start="offboard",
        link_outages=parse_outages(opts.link_outages, s.M),
        impairment=world_impairment(s, opts.link_impairment),
    )
    return WorldBeside(lambda stop: run_world(s, world_opts, stop), initial_errors(s, seed))


async def run_embedded(
    s: Scenario,
    opts: LiveOptions,
    stop: asyncio.Event,
    on_slot: Callable[[SlotEvent], None] | None = None,
    on_status: Callable[[str], None] | None = None,
    on_tracks: Callable[[TracksSlot, float], None] | None = None,
    leave: asyncio.Event | None = None,
) -> LiveResult:
    """World, bridges and ground loop in this process, over loopback UDP MAVLink and Zenoh
    (`run_mission` with `embedded_world`, its ports given as plain events and callbacks, for
    scripts and tests; `leave` None: the landing is always waited for)."""
    from isac_mission.service.assembly import run_serve

    world = embedded_world(s, opts)
    return await run_serve(s, opts, stop, on_slot, on_status, on_tracks, leave, world)
