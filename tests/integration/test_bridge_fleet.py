"""A `BridgeFleet` of three vehicles of the real `sim.world.World` (vehicles, clock, sensing) in
the test's event loop: the test plays the ground loop, answering slot n's detections with plan
n + 1, and checks where the vehicles were measured; then the fleet lands.
"""

from __future__ import annotations

import asyncio
import contextlib

import numpy as np
import pytest

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.config import Scenario
from isac_mission.mavwire.modes import FlightMode
from isac_mission.service.bridge.clock_time import ClockSimTime
from isac_mission.service.bridge.fleet import BridgeFleet
from isac_mission.types import SlotPlan, SolveReport
from isac_mission.wire import DetectionMsg, PlanMsg, decode, encode
from sim.world import World
from sim.world_options import WorldOptions
from tests.support.bridge_rig import (
    ALTITUDE_M,
    ARRIVE_TOL_M,
    KEYS,
    SPEED,
    TIMEOUT_S,
    distance_m,
)
from tests.support.ports import sitl_ports

pytestmark = pytest.mark.timeout(120)


def plan_msg(slot: int, waypoints: np.ndarray) -> PlanMsg:
    m = len(waypoints)
    plan = SlotPlan(
        uav_xy_m=waypoints,
        bs_of_uav=np.zeros(m, dtype=np.int64),
        bandwidth_share=np.full(m, 1.0 / m),
        pcrb_trace=1.0,
        report=SolveReport(status="ok"),
    )
    return PlanMsg.from_plan(slot, 0.0, plan)


async def test_fleet_prepares_follows_plans_and_lands_three_vehicles_of_the_world(
    paper: Scenario, hub: ZenohBus, free_tcp_port: int
) -> None:
    scenario = paper.with_changes(H=ALTITUDE_M, dt=2.0, mission_id=KEYS.mission)
    n_uavs = scenario.M
    assert n_uavs == 3
    endpoint = hub.settings.listen[0]
    options = WorldOptions(
        speed=SPEED,
        bus=BusSettings(connect=(endpoint,)),
        **sitl_ports(n_uavs).world_kwargs(),
        start="offboard",
    )
    world = World(scenario, options)
    stop = asyncio.Event()
    world_task: asyncio.Task[None] | None = None
    time_source = ClockSimTime()
    fleet = BridgeFleet.from_scenario(
        scenario, time_source, hub, base_port=options.mavlink_base_port
    )
    try:
        await world.open()
        world_task = asyncio.create_task(world.run(stop))
        async with fleet, hub.subscribe(KEYS.detections_all) as detections:
            follow = asyncio.create_task(fleet.follow_plans())
            # The ground loop, running from the start: after slot n's detections, publish
            # plan n + 1; collect where the vehicles were measured.
            starts = scenario.uav_start_xy
            plans = {1: starts + np.array([6.0, 0.0]), 2: starts + np.array([6.0, 5.0])}
            seen: dict[int, dict[int, np.ndarray]] = {}

            async def ground() -> None:
                while len(seen.get(2, {})) < n_uavs:
                    _, payload = await detections.get(TIMEOUT_S)
                    det = decode(DetectionMsg, payload, n_uavs=n_uavs)
                    seen.setdefault(det.slot, {})[det.uav] = det.uav_xy_m
                    if len(seen[det.slot]) == n_uavs and det.slot + 1 in plans:
                        plan = plan_msg(det.slot + 1, plans[det.slot + 1])
                        hub.publish(KEYS.plan, encode(plan))

            ground_task = asyncio.create_task(ground())
            await asyncio.wait_for(fleet.prepare_all(), TIMEOUT_S)
            for v in world.vehicles:
                assert v.state.mode is FlightMode.OFFBOARD
                assert abs(v.state.altitude_m - ALTITUDE_M) <= 1.0
            await asyncio.wait_for(ground_task, TIMEOUT_S)

            for n, waypoints in plans.items():
                for m in range(n_uavs):
                    err = distance_m(seen[n][m], waypoints[m])
                    assert err <= ARRIVE_TOL_M, f"slot {n}, UAV {m}: {err:.2f} m off"
            assert fleet.counters.plans_applied == 2

            await asyncio.wait_for(fleet.land_all(), TIMEOUT_S)
            for v in world.vehicles:
                assert v.state.landed
                assert not v.state.armed
            follow.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await follow
    finally:
        stop.set()
        if world_task is not None:
            await asyncio.wait_for(world_task, TIMEOUT_S)
        await world.close()
