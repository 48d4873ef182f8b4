"""A gap in the bridge's own setpoint stream (the uplink) against a simulated PX4-like vehicle.

The vehicle's offboard-loss failsafe (COM_OF_LOSS_T, 1 s) takes it to HOLD when setpoints stop
arriving; the bridge's position stream (the downlink) may show no gap at all meanwhile: a
stalled process or a simulation catching up after a pause stops only what the bridge sends
(docs/reliability.md, "Faults"). The bridge knows its own stream's gaps: a HOLD after one is the
vehicle's failsafe, not an operator's, and the bridge takes the vehicle back to OFFBOARD, whether
or not the vehicle's "Offboard lost" STATUSTEXT reached it. An operator's HOLD with no gap in
either stream stays an override.

The setpoint sender is paused through the stream's `send` (replaced before the bridge starts,
so its paced loop calls the gate) until the vehicle reports the failsafe HOLD; tests wait for
events with generous wall-clock bounds, never with sleeps.
"""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Callable

import numpy as np
import pytest

from isac_mission.bus import ZenohBus
from isac_mission.mavwire.builders import Target, hold_mode_command
from isac_mission.mavwire.modes import FlightMode
from isac_mission.mavwire.signing import new_encoder, pack
from isac_mission.service.bridge.vehicle import VehicleBridge
from tests.support.bridge_rig import ALTITUDE_M, TIMEOUT_S, Rig, distance_m, make_rig
from tests.support.sim_harness import SimRunner, async_wait_until

pytestmark = pytest.mark.timeout(120)

SPAWN = (50.0, 80.0)
START = np.array([58.0, 74.0])
GOAL = START + np.array([40.0, 0.0])
LEG_S = 20.0
"""The leg to GOAL takes this long (simulation s): the gap comes in the middle of it."""


@pytest.fixture
def rig(sim_runner: Callable[..., SimRunner], hub: ZenohBus) -> Callable[..., Rig]:
    """Factory: `rig(spawn_xy_m=[(x, y)], **autopilot_settings)` starts the vehicles."""
    return make_rig(sim_runner, hub)


class SenderGate:
    """Holds back every setpoint of a bridge while `paused` (installed before `start`)."""

    def __init__(self, bridge: VehicleBridge, monkeypatch: pytest.MonkeyPatch) -> None:
        self.paused = False
        stream = bridge._stream
        send = stream.send

        def gated(periodic: bool = True) -> None:
            if not self.paused:
                send(periodic)

        monkeypatch.setattr(stream, "send", gated)


@pytest.mark.parametrize("announced", [True, False], ids=["announced", "text-lost"])
async def test_a_hold_after_a_gap_in_the_setpoint_stream_is_taken_back_to_offboard(
    rig: Callable[..., Rig],
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    announced: bool,
) -> None:
    """The sender pauses until the vehicle takes its offboard-loss HOLD (its positions keep
    coming), then resumes: the bridge re-enters OFFBOARD once, counts and logs one
    interruption with the gap's length, and the vehicle flies on to its waypoint. `text-lost`:
    the vehicle's "Offboard lost: HOLD" does not reach the bridge (a lossy radio, or another
    wording): the bridge's own record of the gap suffices."""
    caplog.set_level(logging.INFO, logger="isac_mission.service.bridge")
    r = rig([SPAWN])
    bridge = r.bridge()
    gate = SenderGate(bridge, monkeypatch)
    if not announced:
        bridge.link.handlers.pop("STATUSTEXT")
    async with bridge:
        await asyncio.wait_for(bridge.prepare(START, ALTITUDE_M), TIMEOUT_S)
        bridge.set_waypoint(GOAL, r.now_s() + LEG_S)
        t_leg = r.now_s()
        await async_wait_until(lambda: r.now_s() >= t_leg + 2.0, TIMEOUT_S, "the leg under way")
        assert r.vehicle.state.mode is FlightMode.OFFBOARD

        gate.paused = True
        t_pause = r.now_s()
        await async_wait_until(
            lambda: r.vehicle.state.mode is FlightMode.HOLD,
            TIMEOUT_S,
            "the vehicle's offboard-loss HOLD",
        )
        held_after_s = r.now_s() - t_pause
        assert held_after_s >= r.vehicle.param("COM_OF_LOSS_T")
        await bridge.link.wait_for(lambda st: st.mode == "hold", TIMEOUT_S, "HOLD on the link")
        # Its positions kept coming: no gap the downlink could show, no link loss.
        st = bridge.link.status()
        assert st.position_s is not None
        assert st.time_s - st.position_s < bridge.settings.interruption_after_s
        assert not st.lost and bridge.counters.link_interruptions == 0
        await async_wait_until(
            lambda: r.now_s() >= st.time_s + 0.5,
            TIMEOUT_S,
            "the bridge's supervision to see the HOLD",
        )
        assert bridge.override == ""  # a gap in the making is no override
        assert bridge.counters.offboard_reentries == 0  # no OFFBOARD without setpoints
        gate.paused = False

        await async_wait_until(
            lambda: (
                bridge.counters.offboard_reentries >= 1
                and r.vehicle.state.mode is FlightMode.OFFBOARD
            ),
            TIMEOUT_S,
            "the bridge taking the vehicle back to OFFBOARD",
        )
        assert bridge.override == "" and bridge.counters.overrides == 0
        assert bridge.counters.offboard_reentries == 1
        assert bridge.counters.link_interruptions == 1
        said = [m for m in caplog.messages if "link interrupted" in m]
        assert len(said) == 1, said  # once, with the gap's length
        assert said[0].startswith("vehicle 0: HOLD after "), said
        gap_s = float(said[0].removeprefix("vehicle 0: HOLD after ").split(" s ")[0])
        assert gap_s >= held_after_s, (said[0], held_after_s)
        assert ("the vehicle reported the offboard loss" in said[0]) is announced, said

        # The mission goes on: the waypoint is reached in OFFBOARD, the service's to fly.
        await async_wait_until(
            lambda: distance_m(r.vehicle.state.position_xy_m, GOAL) < 1.5,
            TIMEOUT_S,
            "the vehicle at its waypoint",
        )
        assert r.vehicle.state.mode is FlightMode.OFFBOARD
        assert bridge.override == "" and bridge.counters.offboard_reentries == 1


async def test_an_operators_hold_without_a_gap_in_either_stream_stays_an_override(
    rig: Callable[..., Rig],
) -> None:
    """A ground station switches the vehicle to HOLD while the bridge streams steadily: an
    override, kept past the re-entry watch window (3 x interruption_after_s + 2 s), with no
    re-entry and no interruption counted. Speed 4: a stall of the machine must last 0.24 wall
    s to make a gap of the setpoint stream here."""
    r = rig([SPAWN], speed=4.0)
    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.bind(("127.0.0.1", 0))
    try:
        async with r.bridge() as bridge:
            await asyncio.wait_for(bridge.prepare(START, ALTITUDE_M), TIMEOUT_S)
            bridge.set_waypoint(GOAL, r.now_s() + LEG_S)
            t_leg = r.now_s()
            await async_wait_until(lambda: r.now_s() >= t_leg + 2.0, TIMEOUT_S, "under way")

            gcs.sendto(
                pack(hold_mode_command(Target(1)), new_encoder(255, 190)), r.vehicle.gcs_address
            )
            await async_wait_until(
                lambda: bridge.override == "operator: HOLD", TIMEOUT_S, "the override noticed"
            )
            t_taken = r.now_s()
            window_s = 3.0 * bridge.settings.interruption_after_s + 2.0
            await async_wait_until(
                lambda: r.now_s() >= t_taken + window_s + 1.0,
                TIMEOUT_S,
                "the re-entry watch window to pass",
            )
            assert r.vehicle.state.mode is FlightMode.HOLD
            assert bridge.override == "operator: HOLD"
            assert bridge.counters.offboard_reentries == 0
            assert bridge.counters.link_interruptions == 0
            assert bridge.counters.overrides == 1
    finally:
        gcs.close()
