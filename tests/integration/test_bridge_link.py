"""A MAVLink bridge's link supervision against a simulated vehicle: a vehicle whose radio goes
silent is reported lost; when it is heard again the bridge takes it back to OFFBOARD. (Silence,
not a missing HEARTBEAT alone: the link is judged on everything the vehicle sends,
docs/reliability.md.)
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from isac_mission.bus import ZenohBus
from isac_mission.mavwire.builders import Target, message_interval_command
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
            # Due after the radio silence below (a plan past its time is dropped for a hover).
            bridge.set_waypoint(goal, r.now_s() + 120.0)

            # The vehicle stops sending HEARTBEAT: everything else flows, the link is not lost.
            to_vehicle(message_interval_command(Target(1), 0, None))
            quiet_from_s = r.now_s()
            await async_wait_until(
                lambda: r.now_s() > quiet_from_s + 3 * bridge.settings.link_lost_after_s,
                TIMEOUT_S,
                "three link-loss timeouts without a heartbeat",
            )
            assert not bridge.link.status().lost and bridge.counters.link_losses == 0
            to_vehicle(message_interval_command(Target(1), 0, 0.0))
            resumed_s = r.now_s()
            await async_wait_until(
                lambda: (bridge.link.status().heartbeat_s or 0.0) > resumed_s,
                TIMEOUT_S,
                "heartbeats again",
            )
            # Its radio goes silent for 40 s (4 wall s at speed 10, past the 2 s wall floor).
            silent_from_s = r.now_s()
            r.runner.call(lambda: r.vehicle.silence_radio(silent_from_s, 40.0))
            # Lost, with the last mode heard (the subscription also holds the early messages
            # from before the first heartbeat, lost in mode unknown).
            await next_telemetry(sub, lambda t: t.link == "lost" and t.mode == "offboard")
            # Meanwhile it takes its offboard-loss action (HOLD), which the bridge cannot see.
            await async_wait_until(
                lambda: r.vehicle.state.mode is FlightMode.HOLD, TIMEOUT_S, "HOLD"
            )
            assert bridge.counters.link_losses == 1

            # The radio returns: link ok, and the bridge takes the vehicle back to OFFBOARD.
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
