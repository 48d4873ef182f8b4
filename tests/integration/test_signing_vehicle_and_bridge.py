"""MAVLink 2 signing over real loopback UDP: a simulated vehicle obeys, and a bridge believes, only
correctly signed messages, and both count what they drop.

Peers that play the operator, the attacker or a fake vehicle are stock pymavlink `MAVLink`
objects on their own 127.0.0.1 sockets (tests/support/signing_peer.py), so the tests also check
that our signatures interoperate with pymavlink's. Tests wait for events (counters, states,
messages) with generous wall-clock deadlines; nothing sleeps to synchronise.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import pytest

from isac_mission.bus import ZenohBus
from isac_mission.config import DEFAULT_SIGNING_KEY_ENV
from isac_mission.mavwire.builders import arm_command, takeoff_command
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from isac_mission.service.bridge.fleet import BridgeFleet
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.mission_result import mirror_signing_counters, signing_counters
from isac_mission.timebase import WallTime
from isac_mission.wire import HealthMsg, decode, encode
from tests.support.ports import free_port_block
from tests.support.signing_peer import (
    HEX_KEY,
    KEY,
    SIGNING_REASONS,
    TIMEOUT_S,
    VEHICLE,
    WRONG_KEY,
    local_position,
    one_uav_scenario,
    signed_vehicle,
    vehicle_heartbeat,
)
from tests.support.sim_harness import SimRunner, async_wait_until, wait_until

pytestmark = pytest.mark.timeout(150)


# --------------------------------------------------------------------------- 1. the vehicle


def test_vehicle_obeys_only_correctly_signed_commands(
    sim_runner: Callable[..., SimRunner], peers: Any
) -> None:
    ap = signed_vehicle(sim_runner, KEY)
    dest = ap.offboard_address
    unsigned = peers(dest)
    forger = peers(dest, WRONG_KEY)
    operator = peers(dest, KEY)

    unsigned.send(arm_command(VEHICLE))
    wait_until(lambda: ap.rejected["unsigned"] == 1, TIMEOUT_S, "unsigned ARM counted")
    forger.send(arm_command(VEHICLE))
    wait_until(lambda: ap.rejected["bad_signature"] == 1, TIMEOUT_S, "wrongly signed ARM counted")
    # A forged packet with a far-future timestamp must not lock the operator's stream out.
    forger.mav.signing.timestamp = 2**47
    forger.send(arm_command(VEHICLE))
    wait_until(lambda: ap.rejected["bad_signature"] == 2, TIMEOUT_S, "future-dated forgery counted")
    assert not ap.armed and ap.landed

    result, arm_bytes = operator.command(arm_command(VEHICLE))
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    assert ap.armed
    result, _ = operator.command(arm_command(VEHICLE, arm=False))
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    assert not ap.armed
    # The operator's ARM replayed verbatim (from another socket) is refused.
    unsigned.send_raw(arm_bytes)
    wait_until(lambda: ap.rejected["replayed"] == 1, TIMEOUT_S, "replayed ARM counted")
    assert not ap.armed

    assert operator.command(arm_command(VEHICLE))[0] == mavlink2.MAV_RESULT_ACCEPTED
    assert operator.command(takeoff_command(VEHICLE))[0] == mavlink2.MAV_RESULT_ACCEPTED
    wait_until(
        lambda: ap.state.mode is FlightMode.HOLD and not ap.state.landed, TIMEOUT_S, "takeoff"
    )
    assert {r: ap.rejected[r] for r in SIGNING_REASONS} == {
        "unsigned": 1,
        "bad_signature": 2,
        "replayed": 1,
    }
    # Whoever failed the check got nothing back: no ACK, and not even telemetry (a rejected
    # sender does not become a peer of the link). The operator's telemetry is signed with KEY.
    assert unsigned.drain() == [] and unsigned.heard == []
    assert forger.drain() == [] and forger.heard == []
    telemetry = operator.recv_until(lambda m: m.get_type() == "LOCAL_POSITION_NED", TIMEOUT_S)
    assert telemetry is not None and telemetry.get_signed()
    assert not [m for m in operator.heard if m.get_type() == "BAD_DATA"]
    assert ap.signatures_ok >= 4


def test_vehicle_without_signing_accepts_unsigned_commands(
    sim_runner: Callable[..., SimRunner], peers: Any
) -> None:
    """Signing off (the default) behaves as before: unsigned commands are obeyed."""
    ap = signed_vehicle(sim_runner, None)
    client = peers(ap.offboard_address)
    assert client.command(arm_command(VEHICLE))[0] == mavlink2.MAV_RESULT_ACCEPTED
    assert ap.armed
    hb = client.recv_until(lambda m: m.get_type() == "HEARTBEAT", TIMEOUT_S)
    assert hb is not None and not hb.get_header().incompat_flags & 1
    assert not ap.rejected and ap.signatures_ok == 0


# --------------------------------------------------------------------------- 2. the bridge


async def test_bridge_believes_only_correctly_signed_telemetry(
    hub: ZenohBus, peers: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(DEFAULT_SIGNING_KEY_ENV, HEX_KEY)
    scenario = one_uav_scenario(enabled=True, link_id=2)
    base_port = free_port_block(1)
    fleet = BridgeFleet.from_scenario(scenario, WallTime(), hub, base_port=base_port)
    async with fleet:
        link = fleet.bridges[0].link
        dest = ("127.0.0.1", base_port)
        unsigned = peers(dest, system=1, component=1)
        forger = peers(dest, WRONG_KEY, system=1, component=1)
        vehicle = peers(dest, KEY, system=1, component=1)

        for fake in (unsigned, forger):
            fake.send(vehicle_heartbeat(armed=True))
            fake.send(local_position(100.0))
        await async_wait_until(
            lambda: link.errors["unsigned"] == 2 and link.errors["bad_signature"] == 2,
            TIMEOUT_S,
            f"forged telemetry counted (so far {dict(link.errors)})",
        )
        st = link.status()
        # Nothing forged was believed: no vehicle, no address to send commands to.
        assert st.heartbeat_s is None and st.lost and not st.armed
        assert st.position_ned_m is None and st.address is None
        assert not link.received

        vehicle.send(vehicle_heartbeat())
        position_bytes = vehicle.send(local_position(7.0))
        st = await link.wait_for(
            lambda s: s.position_ned_m is not None, TIMEOUT_S, "signed telemetry"
        )
        assert not st.lost and st.mode == "hold" and not st.armed
        assert st.position_ned_m is not None and st.position_ned_m[0] == 7.0
        # The bridge answers the signed vehicle with signed GCS heartbeats.
        hb = await asyncio.to_thread(
            vehicle.recv_until, lambda m: m.get_type() == "HEARTBEAT", TIMEOUT_S
        )
        assert hb is not None and hb.get_signed() and hb.get_srcSystem() == 255
        assert hb.get_header().incompat_flags & 1
        assert not [m for m in vehicle.heard if m.get_type() == "BAD_DATA"]

        # Replayed and forged updates after the genuine one change nothing.
        vehicle.send_raw(position_bytes)
        forger.send(vehicle_heartbeat(armed=True))
        await async_wait_until(
            lambda: link.errors["replayed"] == 1 and link.errors["bad_signature"] == 3,
            TIMEOUT_S,
            f"replay and forgery counted (so far {dict(link.errors)})",
        )
        assert not link.status().armed
        assert {r: link.errors[r] for r in SIGNING_REASONS} == {
            "unsigned": 2,
            "bad_signature": 3,
            "replayed": 1,
        }
        assert link.signatures_ok == 2
        assert unsigned.drain() == [] and forger.drain() == []
        # The same counts reach `health` under their names (cli/mission.py mirrors them).
        report = GroundReport()
        mirror = asyncio.create_task(mirror_signing_counters(fleet, report))
        await async_wait_until(
            lambda: report.counters["mavlink replayed"] == 1, TIMEOUT_S, "mirror"
        )
        mirror.cancel()
        assert signing_counters(fleet) == {
            "mavlink unsigned": 2,
            "mavlink bad_signature": 3,
            "mavlink replayed": 1,
        }
        health = HealthMsg(0, 0.0, "running", dict(report.counters), "", {})
        assert decode(HealthMsg, encode(health)).counters["mavlink bad_signature"] == 3
