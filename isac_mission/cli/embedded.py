"""Embedded mode (`isac-mission run`): the simulated world in the same process as the service.

The only module that imports both `sim` and the service: the world runs as a task beside the
bridges and the ground loop of `isac_mission.cli.mission`, talking over loopback UDP MAVLink and a
Zenoh session the ground side listens on.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence

from isac_mission.bus import ZenohBus
from isac_mission.bus.security import secured_settings
from isac_mission.cli.mission import LiveOptions, LiveResult, fly_mission, ground_endpoint
from isac_mission.config import Scenario
from isac_mission.service.ground.report import SlotEvent
from sim.world import run_world
from sim.world_options import WorldOptions, parse_outages


def check_link_outages(specs: Sequence[str], n_uavs: int) -> None:
    """Validate `--inject-link-loss` specs (`VEHICLE:START_S:DURATION_S`); ValueError if bad."""
    parse_outages(specs, n_uavs)


async def run_embedded(
    s: Scenario,
    opts: LiveOptions,
    stop: asyncio.Event,
    on_slot: Callable[[SlotEvent], None] | None = None,
    on_status: Callable[[str], None] | None = None,
) -> LiveResult:
    """World, bridges and ground loop in this process, over loopback UDP MAVLink and Zenoh."""

    world_stop = asyncio.Event()
    zenoh_cfg, endpoint = s.security.zenoh, ground_endpoint(s, opts)
    hub = secured_settings(zenoh_cfg, s.mission_id, "ground", listen=(endpoint,))
    # The world logs in as the world role, with its password from the hub's own users file.
    world_bus = secured_settings(
        zenoh_cfg, s.mission_id, "world", connect=(endpoint,), login_from_users_file=True
    )
    world_opts = WorldOptions(
        speed=opts.speed,
        lockstep=opts.lockstep,
        seed=opts.seed,
        bus=world_bus,
        mavlink_base_port=opts.mavlink_base_port,
        gcs_base_port=opts.gcs_base_port,
        start="offboard",
        link_outages=parse_outages(opts.link_outages, s.M),
    )
    with ZenohBus.open(hub) as bus:
        world = asyncio.create_task(run_world(s, world_opts, world_stop))
        try:
            return await fly_mission(s, opts, bus, stop, on_slot, on_status)
        finally:
            world_stop.set()
            await asyncio.wait_for(world, timeout=30.0)
