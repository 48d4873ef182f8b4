"""MavlinkLink (isac_mission/mavwire/link.py) without a socket: parsing, state, counting, and
the command protocol.

The link is fed datagrams directly (`datagram_received`) and its transport is a recorder, so the
command/ACK logic runs without UDP; waits are on the events they stand for (the command sent).
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

import numpy as np
import pytest

from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import (
    Target,
    arm_command,
    land_command,
    offboard_mode_command,
)
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.link import MavlinkLink
from isac_mission.mavwire.signing import new_encoder, pack

VEHICLE = Target(system=3, component=1)
VEHICLE_ADDR = ("127.0.0.1", 40000)


def vehicle_bytes(msg: Any, system: int = 3, component: int = 1) -> bytes:
    """Wire bytes of a message sent by the vehicle."""
    return pack(msg, new_encoder(system, component))


def px4_heartbeat(custom_mode: int, armed: bool) -> Any:
    base = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (
        mavlink2.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0
    )
    return mavlink2.MAVLink_heartbeat_message(
        mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, base, custom_mode, 4, 3
    )


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class RecordingTransport(asyncio.DatagramTransport):
    """Stands in for the UDP socket: records what is sent."""

    def __init__(self) -> None:
        super().__init__()
        self.sent: list[tuple[bytes, Any]] = []
        self._sent_one = asyncio.Event()

    def sendto(self, data: Any, addr: Any = None) -> None:
        self.sent.append((bytes(data), addr))
        self._sent_one.set()

    async def wait_sent(self, timeout_s: float = 5.0) -> None:
        """Until something has been sent (at most `timeout_s` s)."""
        await asyncio.wait_for(self._sent_one.wait(), timeout_s)

    def is_closing(self) -> bool:
        return False

    def close(self) -> None:
        pass

    def messages(self) -> list[Any]:
        parser = new_encoder(9, 9)
        out: list[Any] = []
        for data, _ in self.sent:
            out.extend(parser.parse_buffer(data) or [])
        return out


def make_link(clock: FakeClock | None = None) -> tuple[MavlinkLink, RecordingTransport]:
    # lost_min_wall_s=0: judge link loss on the fake clock alone.
    link = MavlinkLink(
        0, system_id=3, clock=clock or FakeClock(), lost_after_s=3.0, lost_min_wall_s=0.0
    )
    transport = RecordingTransport()
    link.connection_made(transport)
    return link, transport


# --------------------------------------------------------------------------- link: receiving


def test_link_tracks_vehicle_state_from_its_messages() -> None:
    clock = FakeClock()
    link, _ = make_link(clock)
    assert link.status().lost
    assert link.status().mode == "unknown"
    link.datagram_received(vehicle_bytes(px4_heartbeat(0x00060000, armed=True)), VEHICLE_ADDR)
    link.datagram_received(
        vehicle_bytes(mavlink2.MAVLink_local_position_ned_message(5, 1.0, 2.0, -30.0, 3, 4, -1)),
        VEHICLE_ADDR,
    )
    link.datagram_received(
        vehicle_bytes(
            mavlink2.MAVLink_extended_sys_state_message(
                mavlink2.MAV_VTOL_STATE_MC, mavlink2.MAV_LANDED_STATE_IN_AIR
            )
        ),
        VEHICLE_ADDR,
    )
    link.datagram_received(
        vehicle_bytes(
            mavlink2.MAVLink_global_position_int_message(5, 0, 0, 518_000, 30_000, 0, 0, 0, 0)
        ),
        VEHICLE_ADDR,
    )
    st = link.status()
    assert st.mode == "offboard"
    assert st.armed
    assert st.airborne
    assert not st.lost
    assert st.address == VEHICLE_ADDR
    np.testing.assert_array_equal(st.position_ned_m, [1.0, 2.0, -30.0])
    np.testing.assert_array_equal(st.velocity_ned_mps, [3.0, 4.0, -1.0])
    assert st.altitude_m == 30.0
    assert st.home_amsl_m == pytest.approx(488.0)
    assert st.heartbeat_s == 100.0
    clock.t += 3.5  # no heartbeat for longer than lost_after_s
    assert link.status().lost


def test_link_is_lost_only_when_the_vehicle_is_silent_and_regained_by_a_heartbeat() -> None:
    # A lossy radio drops 1 Hz heartbeats in a row while the 20 Hz stream gets through: any
    # message of the vehicle keeps the link; only a HEARTBEAT (a fresh mode) ends a loss.
    clock = FakeClock()
    link, _ = make_link(clock)
    position = vehicle_bytes(mavlink2.MAVLink_local_position_ned_message(5, 1, 2, -30, 0, 0, 0))
    link.datagram_received(position, VEHICLE_ADDR)
    assert link.status().lost  # no HEARTBEAT yet
    link.datagram_received(vehicle_bytes(px4_heartbeat(0x00060000, armed=True)), VEHICLE_ADDR)
    for _ in range(10):  # 10 s without a heartbeat, a position every second
        clock.t += 1.0
        link.datagram_received(position, VEHICLE_ADDR)
        assert not link.status().lost
    clock.t += 3.5  # silence
    assert link.status().lost
    link.datagram_received(position, VEHICLE_ADDR)  # a position does not end the loss ...
    assert link.status().lost
    link.datagram_received(vehicle_bytes(px4_heartbeat(0x03040000, armed=True)), VEHICLE_ADDR)
    st = link.status()  # ... a heartbeat does, with the mode it carries
    assert not st.lost and st.mode == "hold"


def test_garbage_bad_crc_and_truncation_are_counted_and_parsing_goes_on() -> None:
    link, _ = make_link()
    good = vehicle_bytes(px4_heartbeat(0x03040000, armed=False))
    link.datagram_received(b"\x00\x01garbage bytes", VEHICLE_ADDR)
    corrupt = bytearray(good)
    corrupt[-3] ^= 0xFF
    link.datagram_received(bytes(corrupt), VEHICLE_ADDR)
    link.datagram_received(good[:7], VEHICLE_ADDR)
    link.datagram_received(good, VEHICLE_ADDR)
    assert link.errors["garbage"] == 1
    assert link.errors["bad_crc"] == 1
    assert link.errors["truncated"] == 1
    assert link.received["HEARTBEAT"] == 1
    assert link.status().mode == "hold"


def test_other_systems_and_components_are_ignored() -> None:
    link, _ = make_link()
    link.datagram_received(vehicle_bytes(px4_heartbeat(0x00060000, True), system=7), VEHICLE_ADDR)
    link.datagram_received(
        vehicle_bytes(px4_heartbeat(0x00060000, True), component=100), VEHICLE_ADDR
    )
    assert link.ignored["other_system"] == 1
    assert link.ignored["other_component"] == 1
    assert link.status().heartbeat_s is None


def test_handler_exception_is_counted_and_does_not_stop_the_link(
    caplog: pytest.LogCaptureFixture,
) -> None:
    link, _ = make_link()

    def broken(msg: Any) -> None:
        raise RuntimeError("boom")

    link.on("LOCAL_POSITION_NED", broken)
    pos = mavlink2.MAVLink_local_position_ned_message(5, 1.0, 2.0, -3.0, 0, 0, 0)
    with caplog.at_level(logging.ERROR):
        link.datagram_received(vehicle_bytes(pos), VEHICLE_ADDR)
        link.datagram_received(vehicle_bytes(px4_heartbeat(0x00060000, True)), VEHICLE_ADDR)
    assert link.errors["handler_error"] == 1
    assert "boom" in caplog.text
    assert link.status().position_ned_m is not None  # the built-in handler ran first
    assert link.status().mode == "offboard"  # and later messages are still handled


def test_unhandled_type_is_noted_once_and_counted(caplog: pytest.LogCaptureFixture) -> None:
    link, _ = make_link()
    msg = mavlink2.MAVLink_vfr_hud_message(1.0, 1.0, 0, 50, 10.0, 0.0)
    with caplog.at_level(logging.INFO, logger="isac_mission.mavwire.link"):
        for _ in range(3):
            link.datagram_received(vehicle_bytes(msg), VEHICLE_ADDR)
    assert link.ignored["unhandled:VFR_HUD"] == 3
    assert caplog.text.count("VFR_HUD") == 1


# --------------------------------------------------------------------------- link: commands


def ack(command: int, result: int) -> bytes:
    return vehicle_bytes(mavlink2.MAVLink_command_ack_message(command, result, 0, 0, 255, 190))


async def test_command_returns_on_accepted_ack() -> None:
    link, transport = make_link()
    link.datagram_received(vehicle_bytes(px4_heartbeat(0, False)), VEHICLE_ADDR)
    task = asyncio.create_task(link.command(arm_command(link.target), timeout_s=5.0))
    await transport.wait_sent()  # the command went out
    link.datagram_received(ack(400, mavlink2.MAV_RESULT_IN_PROGRESS), VEHICLE_ADDR)
    link.datagram_received(ack(22, mavlink2.MAV_RESULT_ACCEPTED), VEHICLE_ADDR)  # not ours
    assert not task.done()
    link.datagram_received(ack(400, mavlink2.MAV_RESULT_ACCEPTED), VEHICLE_ADDR)
    await asyncio.wait_for(task, 5.0)
    sent = transport.messages()
    assert [m.get_type() for m in sent] == ["COMMAND_LONG"]  # IN_PROGRESS: no resend
    assert transport.sent[0][1] == VEHICLE_ADDR


async def test_denied_command_raises_naming_command_and_result() -> None:
    link, transport = make_link()
    link.datagram_received(vehicle_bytes(px4_heartbeat(0, False)), VEHICLE_ADDR)
    task = asyncio.create_task(link.command(offboard_mode_command(link.target), timeout_s=5.0))
    await transport.wait_sent()  # the command went out
    link.datagram_received(ack(176, mavlink2.MAV_RESULT_DENIED), VEHICLE_ADDR)
    with pytest.raises(LinkError, match=r"MAV_CMD_DO_SET_MODE.*MAV_RESULT_DENIED"):
        await asyncio.wait_for(task, 5.0)


async def test_unanswered_command_is_retried_with_confirmation_then_times_out() -> None:
    link, transport = make_link()
    link.datagram_received(vehicle_bytes(px4_heartbeat(0, False)), VEHICLE_ADDR)
    with pytest.raises(LinkError, match=r"MAV_CMD_NAV_LAND.*3 attempts.*timeout"):
        await link.command(land_command(link.target), timeout_s=0.01, attempts=3)
    sent = transport.messages()
    assert [m.confirmation for m in sent] == [0, 1, 2]


async def test_command_before_the_vehicle_is_heard_fails() -> None:
    link, _ = make_link()
    with pytest.raises(LinkError, match="no link to the vehicle"):
        await link.command(arm_command(link.target))
