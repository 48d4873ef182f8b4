"""The simulated vehicle's PX4 modes against the real MAVSDK (mavsdk 4.x native binding, asyncio
API): `action.goto_location` (DO_REPOSITION), `action.return_to_launch` (AUTO.RTL),
`action.kill` (force disarm in the air), the battery plugin (BATTERY_STATUS), and a mission
uploaded, downloaded and flown with the mission_raw plugin (AUTO.MISSION).

MAVSDK connects as PX4's offboard client does (`udpin://127.0.0.1:PORT`, the vehicle sending to
PORT); the simulation runs at `SPEED` x real time in its own thread.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator
from typing import Any, TypeVar

import numpy as np
import pytest

from isac_mission.frames import ned_to_geodetic
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.battery import BatterySettings
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from tests.support.ports import free_udp_ports
from tests.support.sim_harness import SimRunner, async_wait_until

mavsdk = pytest.importorskip("mavsdk.asyncio")
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import FlightMode as MavsdkFlightMode  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem, MissionRawError  # noqa: E402

pytestmark = pytest.mark.timeout(150)

T = TypeVar("T")
SPEED = 4.0
TAKEOFF_ALT_M = 10.0
RETURN_ALT_M = 20.0


async def first(stream: AsyncIterator[T], timeout_s: float = 10.0) -> T:
    """The next item of a MAVSDK subscription (closing the subscription)."""
    try:
        return await asyncio.wait_for(anext(stream), timeout_s)
    finally:
        await stream.aclose()  # type: ignore[attr-defined]


async def until(stream: AsyncIterator[T], ok: Any, timeout_s: float = 30.0) -> T:
    """The first item of a MAVSDK subscription for which `ok(item)` holds."""

    async def scan() -> T:
        async for item in stream:
            if ok(item):
                return item
        raise AssertionError("subscription ended")

    try:
        return await asyncio.wait_for(scan(), timeout_s)
    finally:
        await stream.aclose()  # type: ignore[attr-defined]


def start(sim_runner: Any, **overrides: Any) -> tuple[SimRunner, Autopilot, int]:
    offboard_port, gcs_port, bind, gcs_bind = free_udp_ports(4)
    settings = AutopilotSettings(
        index=0,
        offboard_port=offboard_port,
        gcs_port=gcs_port,
        bind_port=bind,
        gcs_bind_port=gcs_bind,
        takeoff_alt_m=TAKEOFF_ALT_M,
        rtl_return_alt_m=RETURN_ALT_M,
        rtl_descend_alt_m=RETURN_ALT_M / 2,
        **overrides,
    )
    runner = sim_runner([settings], speed=SPEED)
    return runner, runner.autopilots[0], offboard_port


async def connect(mav: Mavsdk, port: int) -> Any:
    await mav.add_any_connection(f"udpin://127.0.0.1:{port}")

    async def found() -> Any:
        for system in await mav.get_systems():
            if await system.has_autopilot() and await system.is_connected():
                return system
        return None

    for _ in range(400):
        system = await found()
        if system is not None:
            return system
        await asyncio.sleep(0.05)
    raise AssertionError("no autopilot connected")


def geo_of(ap: Autopilot, ned: tuple[float, float, float]) -> Any:
    s = ap.settings
    return ned_to_geodetic(np.array(ned), s.local_origin_xy_m, s.geo_origin)


async def take_off(ap: Autopilot, action: ActionAsync) -> None:
    await action.arm()
    await action.takeoff()
    await async_wait_until(
        lambda: ap.state.mode is FlightMode.HOLD and abs(ap.state.altitude_m - TAKEOFF_ALT_M) < 0.3,
        40.0,
        "at takeoff altitude",
    )


async def test_mavsdk_goto_location_return_to_launch_and_kill(sim_runner) -> None:
    _runner, ap, port = start(sim_runner)
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mav:
        system = await connect(mav, port)
        action, telemetry = ActionAsync(system), TelemetryAsync(system)
        await take_off(ap, action)

        target = (40.0, -30.0, -15.0)
        geo = geo_of(ap, target)
        await action.goto_location(geo.lat_deg, geo.lon_deg, geo.alt_amsl_m, 90.0)
        await async_wait_until(
            lambda: math.dist(tuple(ap.state.position_ned_m), target) < 0.5, 60.0, "at the goto"
        )
        assert ap.state.mode is FlightMode.HOLD
        assert await first(telemetry.subscribe_flight_mode()) == MavsdkFlightMode.HOLD
        assert ap.state.yaw_rad == pytest.approx(math.pi / 2, abs=0.02)

        await action.return_to_launch()
        assert ap.state.mode is FlightMode.RTL
        await until(
            telemetry.subscribe_flight_mode(), lambda m: m == MavsdkFlightMode.RETURN_TO_LAUNCH
        )
        top = 0.0

        def home_and_disarmed() -> bool:
            nonlocal top
            top = max(top, ap.state.altitude_m)
            return ap.state.landed and not ap.state.armed

        await async_wait_until(home_and_disarmed, 90.0, "landed and disarmed at home")
        assert top == pytest.approx(RETURN_ALT_M, abs=0.5)
        assert math.hypot(*ap.state.position_ned_m[:2]) < 1.0
        assert not await until(telemetry.subscribe_armed(), lambda armed: not armed)

        await take_off(ap, action)
        await action.kill()
        assert not ap.state.armed
        await async_wait_until(lambda: ap.state.landed, 20.0, "dropped to the ground")
        assert ap.state.altitude_m == 0.0 and not ap.state.armed


async def test_mavsdk_battery_plugin_reads_the_energy_model(sim_runner) -> None:
    _runner, ap, port = start(sim_runner, battery=BatterySettings(start_remaining=0.5))
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mav:
        system = await connect(mav, port)
        battery = await first(TelemetryAsync(system).subscribe_battery())
        assert battery.remaining_percent == pytest.approx(50.0, abs=1.0)
        # Half charge: 4 cells at 3.6 + 0.5 * 0.45 V.
        assert battery.voltage_v == pytest.approx(4 * 3.825, abs=0.01)
        assert ap.state.battery_remaining == pytest.approx(0.5, abs=0.01)


def raw_item(seq: int, command: int, geo: Any = None, alt_m: float = TAKEOFF_ALT_M) -> MissionItem:
    """A MISSION_ITEM_INT in the relative-altitude frame (lat/lon 0 without `geo`)."""
    x, y = (round(geo.lat_deg * 1e7), round(geo.lon_deg * 1e7)) if geo is not None else (0, 0)
    return MissionItem(
        seq=seq,
        frame=mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        command=command,
        current=int(seq == 0),
        autocontinue=1,
        param1=0.0,
        param2=0.0,
        param3=0.0,
        param4=float("nan"),
        x=x,
        y=y,
        z=alt_m,
        mission_type=0,
    )


async def test_mavsdk_mission_raw_uploads_downloads_and_flies_a_plan(sim_runner) -> None:
    _runner, ap, port = start(sim_runner)
    wp1, wp2 = (30.0, 0.0, -TAKEOFF_ALT_M), (30.0, 25.0, -15.0)
    plan = [
        raw_item(0, mavlink2.MAV_CMD_NAV_TAKEOFF),
        raw_item(1, mavlink2.MAV_CMD_NAV_WAYPOINT, geo_of(ap, wp1), TAKEOFF_ALT_M),
        raw_item(2, mavlink2.MAV_CMD_NAV_WAYPOINT, geo_of(ap, wp2), 15.0),
        raw_item(3, mavlink2.MAV_CMD_NAV_LAND, geo_of(ap, (0.0, 25.0, 0.0)), 0.0),
    ]
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mav:
        system = await connect(mav, port)
        mission, action = MissionRawAsync(system), ActionAsync(system)
        await mission.upload_mission(plan)
        got = await mission.download_mission()
        assert [(i.seq, i.command, i.frame, i.x, i.y, i.z) for i in got] == [
            (i.seq, i.command, i.frame, i.x, i.y, i.z) for i in plan
        ]
        # An item it does not fly is refused, naming it; the plan stays.
        loiter = raw_item(1, mavlink2.MAV_CMD_NAV_LOITER_TIME, geo_of(ap, wp1))
        with pytest.raises(MissionRawError) as refused:
            await mission.upload_mission([plan[0], loiter])
        assert "unsupported" in str(refused.value).lower()
        assert len(await mission.download_mission()) == len(plan)

        await action.arm()
        await mission.start_mission()
        assert ap.state.mode is FlightMode.MISSION
        passed: set[int] = set()

        def progress() -> bool:
            p = tuple(ap.state.position_ned_m)
            # Each waypoint is reached within NAV_ACC_RAD (2 m) and NAV_MC_ALT_RAD (0.8 m).
            passed.update(k for k, w in enumerate((wp1, wp2)) if math.dist(p, w) < 2.2)
            return ap.state.landed and not ap.state.armed and ap.state.time_s > 5.0

        await async_wait_until(progress, 120.0, "mission flown, landed and disarmed")
        assert passed == {0, 1}
        assert math.dist(tuple(ap.state.position_ned_m[:2]), (0.0, 25.0)) < 1.0
        assert await mission.is_mission_finished()
