"""One MAVLink bridge against a simulated PX4-like vehicle over real loopback UDP and Zenoh:
the mission start, telemetry in the scenario frame, plans reached at their slot boundaries,
landing. The rig (tests/support/bridge_rig.py) publishes a real Zenoh clock; tests wait for
events with generous wall-clock deadlines; nothing sleeps to synchronise.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

import numpy as np
import pytest

from isac_mission.bus import ZenohBus
from isac_mission.mavwire.modes import FlightMode
from tests.support.bridge_rig import (
    ALTITUDE_M,
    ARRIVE_TOL_M,
    KEYS,
    MIN_RATE_HZ,
    TIMEOUT_S,
    V_MAX_MPS,
    Rig,
    distance_m,
    make_rig,
    next_telemetry,
)
from tests.support.sim_harness import SIM_TICK_HZ, SimRunner, async_wait_until

pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def rig(sim_runner: Callable[..., SimRunner], hub: ZenohBus) -> Callable[..., Rig]:
    """Factory: `rig(spawn_xy_m=[(x, y)], **autopilot_settings)` starts the vehicles."""
    return make_rig(sim_runner, hub)


async def test_prepare_arms_takes_off_enters_offboard_and_reaches_the_start_point(
    rig: Callable[..., Rig],
) -> None:
    r = rig([(50.0, 80.0)])
    start = np.array([58.0, 74.0])  # 10 m from the spawn point
    async with r.bridge() as bridge:
        t0 = r.now_s()
        await asyncio.wait_for(bridge.prepare(start, ALTITUDE_M), TIMEOUT_S)
        st = r.vehicle.state
        assert st.armed
        assert not st.landed
        assert st.mode is FlightMode.OFFBOARD
        assert abs(st.altitude_m - ALTITUDE_M) <= bridge.settings.altitude_tolerance_m
        assert distance_m(st.position_xy_m, start) <= bridge.settings.arrive_tolerance_m
        assert bridge.ready
        assert bridge.streaming
        # Taking off took simulation time (no shortcut): at least the climb at <= 3 m/s.
        assert r.now_s() - t0 >= ALTITUDE_M / 3.0
        # No setpoint had to be clamped or dropped by the vehicle (e.g. below its minimum
        # altitude while still on the ground).
        assert not r.vehicle.rejected


async def test_telemetry_on_zenoh_matches_the_vehicle_in_the_scenario_frame(
    rig: Callable[..., Rig], hub: ZenohBus
) -> None:
    origin = (100.0, 50.0)  # the vehicle's local NED origin in the scenario plane
    spawn = (130.0, 90.0)  # local NED: north 40, east 30
    r = rig([spawn], local_origin_xy_m=origin)
    # The constant-speed carrot (not the smooth legs), so that the cruise velocity is known.
    bridge_cm = r.bridge(origin_xy_m=origin, smooth_legs=False)
    async with bridge_cm as bridge, hub.subscribe(KEYS.telemetry(0)) as sub:
        await asyncio.wait_for(bridge.prepare(spawn, ALTITUDE_M), TIMEOUT_S)

        # Hovering: position, altitude and state agree with the vehicle's own.
        t_ready = bridge.time.now_s()
        tel = await next_telemetry(sub, lambda t: t.t_s >= t_ready)
        st = r.vehicle.state
        assert tel.uav == 0
        np.testing.assert_allclose(tel.position_xy_m, st.position_xy_m, atol=0.1)
        assert tel.altitude_m == pytest.approx(st.altitude_m, abs=0.1)
        assert (tel.mode, tel.armed, tel.landed, tel.link) == ("offboard", True, False, "ok")

        # Rate: >= 10 Hz of simulation time. The loop is paced on the wall clock and skips the
        # ticks a stall of its event loop overran (pacing.py), so a count over a window measures
        # the machine's load; the median spacing of the messages' simulation stamps does not
        # (a stall stretches a few intervals). Each stamp is when a position arrived, on the
        # vehicles' 50 Hz simulation tick: one tick of quantisation.
        stamps: list[float] = []
        t_start = r.now_s()
        while r.now_s() < t_start + 3.0:
            stamps.append((await next_telemetry(sub)).t_s)
        spacing_s = float(np.median(np.diff(stamps)))
        assert spacing_s <= 1.0 / MIN_RATE_HZ + 1.0 / SIM_TICK_HZ, f"median spacing {spacing_s} s"

        # Cruising east then north-east: velocity (east, north) and position agree.
        goal = np.array([spawn[0] + 40.0, spawn[1] + 20.0])
        leg_s = 10.0
        t_leg = r.now_s()
        bridge.set_waypoint(goal, t_leg + leg_s)
        await async_wait_until(lambda: r.now_s() >= t_leg + leg_s / 2, TIMEOUT_S, "mid-leg")
        t_mid = bridge.time.now_s()
        tel = await next_telemetry(sub, lambda t: t.t_s >= t_mid)
        st = r.vehicle.state
        v_en = np.array([st.velocity_ned_mps[1], st.velocity_ned_mps[0]])
        # The frame: the velocity points east-north-east along the leg (north and east swapped
        # would point 37 degrees off). Its speed is the leg's 44.7 m in 10 s or more: a stall
        # of the machine that delays the leg's start or holds the vehicle back shortens the
        # time left, and the carrot (or the vehicle catching up with it) flies faster.
        heading_deg = math.degrees(math.atan2(v_en[1], v_en[0]))
        assert heading_deg == pytest.approx(math.degrees(math.atan2(2.0, 4.0)), abs=3.0)
        assert math.hypot(4.0, 2.0) - 0.3 <= float(np.hypot(*v_en)) <= V_MAX_MPS + 0.3
        np.testing.assert_allclose(tel.velocity_xy_mps, v_en, atol=0.3)
        # tel is up to a few hundredths of a simulation second older than st.
        expected = st.position_xy_m - v_en * (st.time_s - tel.t_s)
        np.testing.assert_allclose(tel.position_xy_m, expected, atol=1.0)


async def test_two_successive_plans_are_reached_at_their_slot_boundaries(
    rig: Callable[..., Rig],
) -> None:
    slot_s = 4.0
    start = np.array([200.0, 200.0])
    r = rig([tuple(start)], slot_s=slot_s)
    async with r.bridge() as bridge:
        await asyncio.wait_for(bridge.prepare(start, ALTITUDE_M), TIMEOUT_S)
        waypoints = [
            start + np.array([20.0, 0.0]),
            start + np.array([20.0, -16.0]),
        ]  # 5 m/s, then 4 m/s
        rec = r.recorder()
        t0 = math.ceil(r.now_s()) + 1.0
        boundaries = [rec.watch(t0 + k * slot_s) for k in range(3)]
        r.clock.mission_t0_s = t0
        for k, wp in enumerate(waypoints):
            await asyncio.wait_for(boundaries[k].wait(), TIMEOUT_S)  # slot k measured
            bridge.set_waypoint(wp, t0 + (k + 1) * slot_s)  # plan k + 1 arrives
        await asyncio.wait_for(boundaries[2].wait(), TIMEOUT_S)

    snaps = [rec.snapshots[t0 + k * slot_s] for k in range(3)]
    for k, wp in enumerate(waypoints):
        st = snaps[k + 1].states[0]
        assert st.mode is FlightMode.OFFBOARD
        err = distance_m(st.position_xy_m, wp)
        assert err <= ARRIVE_TOL_M, f"plan {k + 1}: {err:.2f} m from the waypoint at the boundary"
    sent = snaps[2].setpoints_sent[0] - snaps[0].setpoints_sent[0]
    rate_hz = sent / (snaps[2].time_s - snaps[0].time_s)
    assert rate_hz >= MIN_RATE_HZ, f"setpoints at {rate_hz:.1f} Hz of simulation time"


async def test_land_of_a_vehicle_never_heard_is_nothing_to_do(hub: ZenohBus) -> None:
    """No vehicle behind the bridge's port (a `serve` whose world never came): landing is no
    error, since nothing was ever commanded to it; the bridge stays idle."""
    from isac_mission.service.bridge.clock_time import ClockSimTime
    from isac_mission.service.bridge.settings import BridgeSettings
    from isac_mission.service.bridge.vehicle import VehicleBridge
    from tests.support.ports import free_udp_ports

    (port,) = free_udp_ports(1)
    settings = BridgeSettings(index=0, port=port, v_max_mps=V_MAX_MPS)
    async with VehicleBridge(settings, ClockSimTime(), KEYS, hub) as bridge:
        await asyncio.wait_for(bridge.land(), TIMEOUT_S)
        assert bridge.phase == "idle"


async def test_land_lands_and_disarms(rig: Callable[..., Rig], hub: ZenohBus) -> None:
    r = rig([(10.0, 10.0)])
    async with r.bridge() as bridge, hub.subscribe(KEYS.telemetry(0)) as sub:
        await asyncio.wait_for(bridge.prepare((10.0, 10.0), ALTITUDE_M), TIMEOUT_S)
        assert r.vehicle.state.altitude_m > ALTITUDE_M - 1.0
        await asyncio.wait_for(bridge.land(), TIMEOUT_S)
        st = r.vehicle.state
        assert st.landed
        assert not st.armed
        assert st.altitude_m < 0.1
        assert bridge.phase == "landed"
        assert not bridge.streaming
        # The flags (heartbeat, EXTENDED_SYS_STATE) may come before the last position: wait
        # (bounded) for telemetry that says landed, disarmed and on the ground at once.
        # (A TimeoutError fails the test.)
        await next_telemetry(sub, lambda t: t.landed and not t.armed and t.altitude_m < 0.1)
