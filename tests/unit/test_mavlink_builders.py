"""The pure MAVLink message builders of isac_mission/mavwire/builders.py, without a socket.

Builders are checked field by field and again after a round trip through pymavlink's wire format
(what the vehicle parses).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

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
    request_position_command,
    takeoff_command,
)
from isac_mission.mavwire.dialect import mavlink2
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


def test_request_position_command_asks_for_local_position_ned_once() -> None:
    req = wire(request_position_command(VEHICLE))
    assert req.command == mavlink2.MAV_CMD_REQUEST_MESSAGE
    assert req.param1 == mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED == 32
    assert (req.target_system, req.target_component) == (3, 1)


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


def test_command_names_for_errors() -> None:
    assert command_name(22) == "MAV_CMD_NAV_TAKEOFF"
    assert command_name(65000) == "command 65000"
