"""A MAVLink bridge's link supervision against a simulated vehicle: a vehicle whose HEARTBEAT
stops is reported lost; when heartbeats return the bridge takes it back to OFFBOARD.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from isac_mission.bus import ZenohBus
from isac_mission.mavwire.builders import Target, hold_mode_command, message_interval_command
from isac_mission.mavwire.modes import FlightMode
from isac_mission.mavwire.signing import new_encoder, pack
from tests.support.bridge_rig import (
    ALTITUDE_M,
    KEYS,
    TIMEOUT_S,
    Rig,
    distance_m,
    make_rig,
    next_telemetry,
)
from tests.support.sim_harness import SimRunner, async_wait_until

pytestmark = pytest.mark.timeout(120)


@pytest.fixture
def rig(sim_runner: Callable[..., SimRunner], hub: ZenohBus) -> Callable[..., Rig]:
    """Factory: `rig(spawn_xy_m=[(x, y)], **autopilot_settings)` starts the vehicles."""
    return make_rig(sim_runner, hub)


async def test_link_lost_is_reported_and_offboard_resumes_when_heartbeats_return(
    rig: Callable[..., Rig], hub: ZenohBus
) -> None:
    # No wall-clock keep-alive: a vehicle that stops its HEARTBEAT stream is silent.
    r = rig([(300.0, 300.0)], heartbeat_keepalive_wall_s=None)
    tester = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tester.bind(("127.0.0.1", 0))
    encoder = new_encoder(200, 190)

    def to_vehicle(msg: Any) -> None:
        tester.sendto(pack(msg, encoder), r.vehicle.offboard_address)

    try:
        async with r.bridge() as bridge, hub.subscribe(KEYS.telemetry(0)) as sub:
            await asyncio.wait_for(bridge.prepare((300.0, 300.0), ALTITUDE_M), TIMEOUT_S)
            goal = np.array([330.0, 300.0])
            bridge.set_waypoint(goal, r.now_s() + 20.0)

            # The vehicle stops sending HEARTBEAT (everything else keeps flowing).
            to_vehicle(message_interval_command(Target(1), 0, None))
            lost = await next_telemetry(sub, lambda t: t.link == "lost")
            assert lost.mode == "offboard"  # the last mode heard
            # Meanwhile it takes its loss action (HOLD), which the bridge cannot see yet.
            to_vehicle(hold_mode_command(Target(1)))
            await async_wait_until(
                lambda: r.vehicle.state.mode is FlightMode.HOLD, TIMEOUT_S, "HOLD"
            )
            assert bridge.counters.link_losses == 1

            # Heartbeats return: link ok, and the bridge takes the vehicle back to OFFBOARD.
            to_vehicle(message_interval_command(Target(1), 0, 0.0))
            await next_telemetry(sub, lambda t: t.link == "ok")
            await next_telemetry(sub, lambda t: t.mode == "offboard" and t.link == "ok")
            assert r.vehicle.state.mode is FlightMode.OFFBOARD
            assert bridge.counters.offboard_reentries == 1
            # ... and it carries on to the waypoint from where it held.
            await async_wait_until(
                lambda: distance_m(r.vehicle.state.position_xy_m, goal) < 1.0,
                TIMEOUT_S,
                "arrival at the waypoint after the link came back",
            )
    finally:
        tester.close()
