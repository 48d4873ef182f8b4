"""MAVLink 2 signing over real loopback UDP: a bridge without the key cannot fly a signed vehicle, and a
signed fleet of the world takes off, follows setpoints and lands, its key never in the logs.

Peers that play the operator, the attacker or a fake vehicle are stock pymavlink `MAVLink`
objects on their own 127.0.0.1 sockets (tests/support/signing_peer.py), so the tests also check
that our signatures interoperate with pymavlink's. Tests wait for events (counters, states,
messages) with generous wall-clock deadlines; nothing sleeps to synchronise.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.config import (
    MavlinkSigningKey,
    Scenario,
    load_scenario,
)
from isac_mission.errors import LinkError
from isac_mission.mavwire.modes import FlightMode
from isac_mission.service.bridge.clock_time import ClockSimTime
from isac_mission.service.bridge.fleet import BridgeFleet
from sim.world import World
from sim.world_options import WorldOptions
from tests.support.ports import sitl_ports
from tests.support.signing_peer import (
    ALTITUDE_M,
    HEX_KEY,
    KEY,
    KEYS,
    SIGNING_REASONS,
    SPEED,
    TIMEOUT_S,
    WRONG_KEY,
    bridge_for,
    signed_vehicle,
    write_signing_scenario,
)
from tests.support.sim_harness import SimRunner, async_wait_until

pytestmark = pytest.mark.timeout(150)


# --------------------------------------------------------------------------- 3. end to end


@pytest.mark.parametrize(
    ("bridge_key", "reason"),
    [(None, "unsigned"), (WRONG_KEY, "bad_signature")],
    ids=["unsigned-bridge", "wrong-key-bridge"],
)
async def test_a_bridge_without_the_key_cannot_fly_a_signed_vehicle(
    sim_runner: Callable[..., SimRunner],
    hub: ZenohBus,
    bridge_key: MavlinkSigningKey | None,
    reason: str,
) -> None:
    ap = signed_vehicle(sim_runner, KEY)
    bridge = bridge_for(ap, hub, bridge_key, connect_timeout_s=3.0, command_attempts=2)
    async with bridge:
        with pytest.raises(LinkError):
            await asyncio.wait_for(bridge.prepare((0.0, 10.0), ALTITUDE_M), TIMEOUT_S)
        if bridge_key is None:
            # The bridge cannot check signatures, so it hears the vehicle and sends it unsigned
            # heartbeats and its ARM command: the vehicle refuses and counts them all.
            assert ap.rejected["unsigned"] >= 3
            assert bridge.link.errors["unsigned"] == 0
        else:
            # The vehicle's telemetry fails the bridge's check: the bridge never even learns
            # where the vehicle is, so it sends nothing.
            assert bridge.link.errors["bad_signature"] >= 3
            assert bridge.link.status().address is None
            assert ap.rejected[reason] == 0
    assert not ap.armed and ap.landed


async def test_signed_fleet_of_the_world_takes_off_follows_setpoints_and_lands(
    hub: ZenohBus,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    # The vehicles read the key from a file, the service from an environment variable.
    key_file = tmp_path / "mavlink.key"
    key_file.write_text(HEX_KEY + "\n")
    monkeypatch.setenv("FLEET_KEY", HEX_KEY)
    world_cfg = load_scenario(
        write_signing_scenario(tmp_path, "w.yaml", {"enabled": True, "key_file": str(key_file)})
    )
    service_cfg = load_scenario(
        write_signing_scenario(tmp_path, "s.yaml", {"enabled": True, "key_env": "FLEET_KEY"})
    )
    world_key, service_key = world_cfg.mavlink_signing_key, service_cfg.mavlink_signing_key
    assert world_key is not None and service_key is not None
    assert world_key.source != service_key.source and world_key.secret == service_key.secret

    def flying(s: Scenario) -> Scenario:
        return s.with_changes(H=ALTITUDE_M, dt=2.0, mission_id=KEYS.mission)

    world_cfg, service_cfg = flying(world_cfg), flying(service_cfg)
    n = world_cfg.M
    options = WorldOptions(
        speed=SPEED,
        bus=BusSettings(connect=(hub.settings.listen[0],)),
        **sitl_ports(n).world_kwargs(),
        start="offboard",
    )
    world = World(world_cfg, options)
    stop = asyncio.Event()
    world_task: asyncio.Task[None] | None = None
    fleet = BridgeFleet.from_scenario(
        service_cfg, ClockSimTime(), hub, base_port=options.mavlink_base_port
    )
    try:
        await world.open()
        world_task = asyncio.create_task(world.run(stop))
        async with fleet:
            await asyncio.wait_for(fleet.prepare_all(), 2 * TIMEOUT_S)
            for v in world.vehicles:
                assert v.armed and v.state.mode is FlightMode.OFFBOARD
                assert abs(v.state.altitude_m - ALTITUDE_M) <= 1.0
            goals = world_cfg.uav_start_xy + np.array([6.0, -4.0])
            for bridge, goal in zip(fleet.bridges, goals, strict=True):
                bridge.set_waypoint(goal, None)
            await async_wait_until(
                lambda: all(
                    math.dist(v.state.position_xy_m, g) <= 1.0
                    for v, g in zip(world.vehicles, goals, strict=True)
                ),
                TIMEOUT_S,
                "every vehicle at its offboard setpoint",
            )
            await asyncio.wait_for(fleet.land_all(), 2 * TIMEOUT_S)
            for v in world.vehicles:
                assert v.state.landed and not v.armed
                # Everything the vehicle obeyed was signed; nothing failed the check.
                assert v.signatures_ok > 0
                assert not any(v.rejected[r] for r in SIGNING_REASONS)
            for bridge in fleet.bridges:
                assert bridge.link.signatures_ok > 0
                assert not any(bridge.link.errors[r] for r in SIGNING_REASONS)
    finally:
        stop.set()
        if world_task is not None:
            await asyncio.wait_for(world_task, TIMEOUT_S)
        await world.close()
    # The logs say signing is on and with which key (by fingerprint), never the key itself.
    assert f"MAVLink signing on (key {KEY.fingerprint}" in caplog.text
    assert HEX_KEY not in caplog.text.lower()
    assert KEY.secret.hex() not in caplog.text and repr(KEY.secret) not in caplog.text
