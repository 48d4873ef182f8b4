"""MavlinkLink without a socket: pure message builders, PX4 mode decoding, parsing and counting.

Builders are checked field by field and again after a round trip through pymavlink's wire format
(what the vehicle parses). The link is fed datagrams directly (`datagram_received`) and its
transport is a recorder, so command/ACK logic runs without UDP.
"""

from __future__ import annotations

import asyncio
import logging
import math
from typing import Any

import numpy as np
import pytest

from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import (
    Target,
    arm_command,
    command_name,
    gcs_heartbeat,
    hold_mode_command,
    land_command,
    message_interval_command,
    offboard_mode_command,
    position_target_local_ned,
    position_type_mask,
    takeoff_command,
)
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.link import MavlinkLink
from isac_mission.mavwire.modes import (
    FlightMode,
    heartbeat_mode_name,
    px4_custom_mode,
    px4_mode_name,
)
from isac_mission.mavwire.signing import new_encoder, pack

VEHICLE = Target(system=3, component=1)
VEHICLE_ADDR = ("127.0.0.1", 40000)


def wire(msg: Any, system: int = 255, component: int = 190) -> Any:
    """`msg` after packing by (system, component) and parsing back, as a vehicle sees it."""
    data = pack(msg, new_encoder(system, component))
    parsed = new_encoder(9, 9).parse_buffer(data)
    assert parsed is not None
    assert len(parsed) == 1
    return parsed[0]


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


# --------------------------------------------------------------------------- builders


def test_gcs_heartbeat_identifies_a_ground_station() -> None:
    hb = wire(gcs_heartbeat())
    assert hb.get_type() == "HEARTBEAT"
    assert hb.type == mavlink2.MAV_TYPE_GCS
    assert hb.autopilot == mavlink2.MAV_AUTOPILOT_INVALID
    assert hb.system_status == mavlink2.MAV_STATE_ACTIVE
    assert hb.get_srcSystem() == 255


@pytest.mark.parametrize(("arm", "param1"), [(True, 1.0), (False, 0.0)])
def test_arm_command_sets_param1(arm: bool, param1: float) -> None:
    msg = wire(arm_command(VEHICLE, arm))
    assert msg.command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM == 400
    assert (msg.target_system, msg.target_component) == (3, 1)
    assert msg.param1 == param1
    assert msg.confirmation == 0


def test_takeoff_command_carries_amsl_altitude_and_keeps_heading() -> None:
    msg = wire(takeoff_command(VEHICLE, 498.0))
    assert msg.command == mavlink2.MAV_CMD_NAV_TAKEOFF == 22
    assert msg.param7 == pytest.approx(498.0)
    assert math.isnan(msg.param4)  # yaw: keep
    assert math.isnan(msg.param5)
    assert math.isnan(msg.param6)
    assert math.isnan(wire(takeoff_command(VEHICLE)).param7)  # vehicle's own altitude


def test_land_command_lands_where_the_vehicle_is() -> None:
    msg = wire(land_command(VEHICLE))
    assert msg.command == mavlink2.MAV_CMD_NAV_LAND == 21
    assert all(math.isnan(p) for p in (msg.param5, msg.param6, msg.param7))


@pytest.mark.parametrize(
    ("builder", "main", "sub"),
    [(offboard_mode_command, 6, 0), (hold_mode_command, 4, 3)],
)
def test_set_mode_commands_use_px4_custom_modes(builder: Any, main: int, sub: int) -> None:
    msg = wire(builder(VEHICLE))
    assert msg.command == mavlink2.MAV_CMD_DO_SET_MODE == 176
    assert msg.param1 == mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert (msg.param2, msg.param3) == (main, sub)


def test_message_interval_command_stops_and_restores_a_stream() -> None:
    stop = wire(message_interval_command(VEHICLE, 0, None))
    assert stop.command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL
    assert (stop.param1, stop.param2) == (0.0, -1.0)
    assert wire(message_interval_command(VEHICLE, 32, 0.05)).param2 == pytest.approx(50_000.0)


@pytest.mark.parametrize(
    ("velocity", "yaw", "mask"),
    [(False, False, 0xDF8), (False, True, 0x9F8), (True, False, 0xDC0), (True, True, 0x9C0)],
)
def test_type_mask_of_each_setpoint_kind(velocity: bool, yaw: bool, mask: int) -> None:
    assert position_type_mask(velocity=velocity, yaw=yaw) == mask


def test_position_target_with_feed_forward_uses_local_ned_and_its_mask() -> None:
    msg = wire(
        position_target_local_ned(
            VEHICLE, np.array([10.0, -20.0, -100.0]), np.array([1.5, -2.5, 0.0]), time_boot_ms=1234
        )
    )
    assert msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert msg.coordinate_frame == mavlink2.MAV_FRAME_LOCAL_NED
    assert msg.type_mask == 0xDC0
    assert (msg.x, msg.y, msg.z) == (10.0, -20.0, -100.0)
    assert (msg.vx, msg.vy, msg.vz) == (1.5, -2.5, 0.0)
    assert (msg.target_system, msg.target_component) == (3, 1)
    assert msg.time_boot_ms == 1234
    # What the vehicle reads from the mask: position and velocity used, the rest ignored.
    for bit in (1, 2, 4, 8, 16, 32):
        assert not msg.type_mask & bit
    for bit in (64, 128, 256, 1024, 2048):
        assert msg.type_mask & bit


def test_position_only_target_ignores_velocity_and_carries_yaw_when_given() -> None:
    msg = wire(position_target_local_ned(VEHICLE, [1.0, 2.0, -3.0], yaw_rad=0.5))
    assert msg.type_mask == 0x9F8
    assert msg.yaw == pytest.approx(0.5)


@pytest.mark.parametrize(
    ("position", "velocity", "yaw"),
    [
        ([math.nan, 0.0, -10.0], None, None),
        ([0.0, 0.0], None, None),
        ([0.0, 0.0, -10.0], [math.inf, 0.0, 0.0], None),
        ([0.0, 0.0, -10.0], None, math.nan),
    ],
)
def test_position_target_rejects_non_finite_or_misshapen_input(
    position: list[float], velocity: list[float] | None, yaw: float | None
) -> None:
    with pytest.raises(ValueError, match=r"finite|3"):
        position_target_local_ned(VEHICLE, position, velocity, yaw)


# --------------------------------------------------------------------------- modes


@pytest.mark.parametrize(
    ("custom_mode", "name"),
    [
        (0x00060000, "offboard"),
        (0x02040000, "takeoff"),
        (0x03040000, "hold"),
        (0x06040000, "land"),
        (0x04040000, "mission"),
        (0x05040000, "rtl"),
        (0x00030000, "posctl"),
        (0x00010000, "manual"),
        (0x07040000, "auto"),
        (0x00000000, "unknown"),
        (0x00630000, "unknown"),
    ],
)
def test_px4_custom_mode_decodes(custom_mode: int, name: str) -> None:
    assert px4_mode_name(custom_mode) == name


def test_px4_modes_agree_with_the_simulated_vehicle() -> None:
    for mode in FlightMode:
        assert px4_mode_name(mode.px4_custom_mode) == mode.value.lower()
    assert px4_custom_mode(6) == FlightMode.OFFBOARD.px4_custom_mode
    assert px4_custom_mode(4, 3) == FlightMode.HOLD.px4_custom_mode


def test_heartbeat_mode_needs_px4_and_the_custom_mode_flag() -> None:
    custom = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_PX4, custom, 0x00060000) == "offboard"
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_PX4, 0, 0x00060000) == "unknown"
    assert heartbeat_mode_name(mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA, custom, 4) == "unknown"


def test_command_names_for_errors() -> None:
    assert command_name(22) == "MAV_CMD_NAV_TAKEOFF"
    assert command_name(65000) == "command 65000"


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
