"""The simulated vehicle against the real MAVSDK (mavsdk 4.x native binding, asyncio API).

MAVSDK connects as PX4's offboard client does (`udpin://127.0.0.1:PORT`, the vehicle sending to
PORT), reads position and health, arms, takes off, flies offboard to a position setpoint 50 m
away, holds and lands; then three vehicles fly at once through one MAVSDK instance.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator
from typing import TypeVar

import numpy as np
import pytest

from isac_mission.frames import scenario_to_geodetic
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.settings import AutopilotSettings
from tests.support.ports import free_udp_ports
from tests.support.sim_harness import SimRunner, async_wait_until

mavsdk = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.offboard import OffboardAsync, PositionNedYaw  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import FlightMode as MavsdkFlightMode  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

pytestmark = pytest.mark.timeout(120)

T = TypeVar("T")

TAKEOFF_ALT_M = 10.0
ARRIVAL_TOL_M = 2.0
SPEED = 4.0


def settings_for(
    index: int, offboard_port: int, gcs_port: int, spawn_xy: tuple[float, float]
) -> AutopilotSettings:
    return AutopilotSettings(
        index=index,
        offboard_port=offboard_port,
        gcs_port=gcs_port,
        bind_port=0,
        gcs_bind_port=0,
        takeoff_alt_m=TAKEOFF_ALT_M,
        local_origin_xy_m=spawn_xy,
        spawn_xy_m=spawn_xy,
    )


async def first(stream: AsyncIterator[T], timeout_s: float = 10.0) -> T:
    """The next item of a MAVSDK subscription (closing the subscription)."""
    try:
        return await asyncio.wait_for(anext(stream), timeout_s)
    finally:
        await stream.aclose()  # type: ignore[attr-defined]


async def connect(mav: Mavsdk, ports: list[int], timeout_s: float = 20.0) -> dict[int, object]:
    """Add one udpin connection per port and return the autopilot systems by system id."""
    for port in ports:
        await mav.add_any_connection(f"udpin://127.0.0.1:{port}")
    found: dict[int, object] = {}

    async def all_found() -> bool:
        for system in await mav.get_systems():
            if await system.has_autopilot() and await system.is_connected():
                found[await system.get_system_id()] = system
        return len(found) >= len(ports)

    deadline = asyncio.get_running_loop().time() + timeout_s
    while not await all_found():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"only systems {sorted(found)} connected within {timeout_s} s")
        await asyncio.sleep(0.05)
    return found


async def fly_mission(
    system: object, runner: SimRunner, index: int, north_m: float, east_m: float
) -> None:
    """Arm, take off, offboard to (north, east) at takeoff altitude, hold, land; assert each step."""
    ap = runner.autopilots[index]
    action = ActionAsync(system)
    offboard = OffboardAsync(system)
    telemetry = TelemetryAsync(system)

    health = await first(telemetry.subscribe_health())
    assert health.is_global_position_ok and health.is_local_position_ok and health.is_armable

    await action.arm()
    assert ap.state.armed
    await action.takeoff()
    await async_wait_until(
        lambda: ap.state.mode is FlightMode.HOLD and abs(ap.state.altitude_m - TAKEOFF_ALT_M) < 0.5,
        40.0,
        f"vehicle {index} at takeoff altitude",
    )
    assert await first(telemetry.subscribe_in_air())

    await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -TAKEOFF_ALT_M, 0.0))
    await offboard.start()
    assert ap.state.mode is FlightMode.OFFBOARD
    await offboard.set_position_ned(PositionNedYaw(north_m, east_m, -TAKEOFF_ALT_M, 0.0))

    def arrived() -> bool:
        p = ap.state.position_ned_m
        return math.dist((p[0], p[1], p[2]), (north_m, east_m, -TAKEOFF_ALT_M)) < ARRIVAL_TOL_M

    await async_wait_until(arrived, 40.0, f"vehicle {index} at the offboard setpoint")
    pv = await first(telemetry.subscribe_position_velocity_ned())
    assert (
        math.hypot(pv.position.north_m - north_m, pv.position.east_m - east_m) < ARRIVAL_TOL_M + 1.0
    )

    await offboard.stop()
    await async_wait_until(
        lambda: ap.state.mode is FlightMode.HOLD, 10.0, "HOLD after offboard stop"
    )
    assert await first(telemetry.subscribe_flight_mode()) == MavsdkFlightMode.HOLD

    await action.land()
    await async_wait_until(
        lambda: ap.state.landed and not ap.state.armed, 60.0, f"vehicle {index} landed and disarmed"
    )


async def test_mavsdk_flies_takeoff_offboard_hold_land(sim_runner) -> None:
    offboard_port, gcs_port = free_udp_ports(2)
    spawn = (30.0, -20.0)
    runner = sim_runner([settings_for(0, offboard_port, gcs_port, spawn)], speed=SPEED)
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mav:
        systems = await connect(mav, [offboard_port])
        system = systems[1]
        telemetry = TelemetryAsync(system)
        position = await first(telemetry.subscribe_position())
        expected = scenario_to_geodetic(
            np.array(spawn), 0.0, runner.autopilots[0].settings.geo_origin
        )
        assert position.latitude_deg == pytest.approx(expected.lat_deg, abs=1e-6)
        assert position.longitude_deg == pytest.approx(expected.lon_deg, abs=1e-6)
        assert position.absolute_altitude_m == pytest.approx(expected.alt_amsl_m, abs=0.01)
        await fly_mission(system, runner, 0, 50.0, 0.0)


async def test_mavsdk_flies_three_vehicles_at_once(sim_runner) -> None:
    ports = free_udp_ports(6)
    spawns = [(0.0, 0.0), (20.0, 0.0), (40.0, 0.0)]
    runner = sim_runner(
        [settings_for(m, ports[m], ports[3 + m], spawns[m]) for m in range(3)], speed=3.0
    )
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mav:
        systems = await connect(mav, ports[:3])
        assert sorted(systems) == [1, 2, 3]
        targets = [(50.0, 0.0), (0.0, 50.0), (-30.0, -40.0)]
        await asyncio.gather(
            *(fly_mission(systems[m + 1], runner, m, *targets[m]) for m in range(3))
        )
    for m, ap in enumerate(runner.autopilots):
        assert ap.system_id == m + 1
        assert not ap.rejected, f"vehicle {m} rejected input: {ap.rejected}"
