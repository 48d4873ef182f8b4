"""Pure MAVLink message builders for a ground station's side of a link.

Each returns a pymavlink message object (pack it with `signing.pack`), so what the service sends
can be checked without a socket: `gcs_heartbeat`, `command_long` and its commands (`arm_command`,
`takeoff_command`, `land_command`, `set_mode_command`, `offboard_mode_command`,
`hold_mode_command`, `message_interval_command`), and `position_target_local_ned`.

Frames and units: MAV_FRAME_LOCAL_NED (north, east, down), m, m/s, rad; arrays are float64 (3,).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import PX4_MAIN_AUTO, PX4_MAIN_OFFBOARD, PX4_SUB_HOLD
from isac_mission.mavwire.ports import AUTOPILOT_COMPONENT_ID
from isac_mission.types import FloatArray


@dataclass(frozen=True)
class Target:
    """The MAVLink address of a vehicle's autopilot: system id and component id."""

    system: int
    component: int = AUTOPILOT_COMPONENT_ID


def command_name(command: int) -> str:
    """ "MAV_CMD_NAV_TAKEOFF" for 22, or "command 12345" if unknown."""
    entry = mavlink2.enums["MAV_CMD"].get(command)
    return str(entry.name) if entry is not None else f"command {command}"


def result_name(result: int) -> str:
    """ "MAV_RESULT_DENIED" for 2, or "result 99" if unknown."""
    entry = mavlink2.enums["MAV_RESULT"].get(result)
    return str(entry.name) if entry is not None else f"result {result}"


def gcs_heartbeat() -> Any:
    """HEARTBEAT of a ground station (MAV_TYPE_GCS, no autopilot, active); send at 1 Hz."""
    return mavlink2.MAVLink_heartbeat_message(
        mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, mavlink2.MAV_STATE_ACTIVE, 3
    )


def command_long(
    target: Target, command: int, params: Sequence[float] = (), confirmation: int = 0
) -> Any:
    """COMMAND_LONG `command` with up to 7 parameters (missing ones are 0)."""
    p = [float(x) for x in params]
    if len(p) > 7:
        raise ValueError(f"COMMAND_LONG takes 7 parameters, got {len(p)}")
    p += [0.0] * (7 - len(p))
    return mavlink2.MAVLink_command_long_message(
        target.system, target.component, command, confirmation, *p
    )


def arm_command(target: Target, arm: bool = True) -> Any:
    """MAV_CMD_COMPONENT_ARM_DISARM: param1 = 1 to arm, 0 to disarm."""
    return command_long(target, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, (1.0 if arm else 0.0,))


def takeoff_command(target: Target, altitude_amsl_m: float = math.nan) -> Any:
    """MAV_CMD_NAV_TAKEOFF from the current position: param7 = altitude AMSL, m (NaN: the
    vehicle's own takeoff altitude, MIS_TAKEOFF_ALT); yaw (param4), latitude and longitude
    (param5, 6) are NaN, i.e. keep heading and take off where the vehicle is."""
    nan = math.nan
    return command_long(
        target, mavlink2.MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, nan, nan, nan, altitude_amsl_m)
    )


def land_command(target: Target) -> Any:
    """MAV_CMD_NAV_LAND where the vehicle is (yaw, latitude, longitude, altitude NaN)."""
    nan = math.nan
    return command_long(target, mavlink2.MAV_CMD_NAV_LAND, (0.0, 0.0, 0.0, nan, nan, nan, nan))


def set_mode_command(target: Target, main_mode: int, sub_mode: int = 0) -> Any:
    """MAV_CMD_DO_SET_MODE to a PX4 custom mode: param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    param2 = main mode, param3 = sub-mode."""
    return command_long(
        target,
        mavlink2.MAV_CMD_DO_SET_MODE,
        (float(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main_mode), float(sub_mode)),
    )


def offboard_mode_command(target: Target) -> Any:
    """DO_SET_MODE to PX4 OFFBOARD (main mode 6)."""
    return set_mode_command(target, PX4_MAIN_OFFBOARD)


def request_position_command(target: Target) -> Any:
    """MAV_CMD_REQUEST_MESSAGE for LOCAL_POSITION_NED: the position now, outside the streams (a
    vehicle whose clock is held, as a lockstep simulation holds it, streams nothing else)."""
    return command_long(
        target,
        mavlink2.MAV_CMD_REQUEST_MESSAGE,
        (float(mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED),),
    )


def hold_mode_command(target: Target) -> Any:
    """DO_SET_MODE to PX4 HOLD (AUTO.LOITER: main mode 4, sub-mode 3)."""
    return set_mode_command(target, PX4_MAIN_AUTO, PX4_SUB_HOLD)


def message_interval_command(target: Target, message_id: int, interval_s: float | None) -> Any:
    """MAV_CMD_SET_MESSAGE_INTERVAL: stream `message_id` every `interval_s` s; None stops it
    (interval -1), 0 restores the vehicle's default rate."""
    interval_us = -1.0 if interval_s is None else interval_s * 1e6
    return command_long(
        target, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, (float(message_id), interval_us)
    )


_MASK_ACCEL: Final = (
    mavlink2.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
_MASK_VELOCITY: Final = (
    mavlink2.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
_MASK_YAW: Final = mavlink2.POSITION_TARGET_TYPEMASK_YAW_IGNORE
_MASK_YAW_RATE: Final = mavlink2.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE


def position_type_mask(*, velocity: bool, yaw: bool) -> int:
    """SET_POSITION_TARGET type_mask using x, y, z, optionally vx, vy, vz (feed-forward) and yaw.

    Acceleration and yaw rate are always ignored. Position only: 0xDF8; position + yaw: 0x9F8
    (MAVSDK's `set_position_ned`); position + velocity: 0xDC0; all three: 0x9C0.
    """
    mask = int(_MASK_ACCEL | _MASK_YAW_RATE)
    if not velocity:
        mask |= _MASK_VELOCITY
    if not yaw:
        mask |= _MASK_YAW
    return mask


def position_target_local_ned(
    target: Target,
    position_ned_m: FloatArray | Sequence[float],
    velocity_ned_mps: FloatArray | Sequence[float] | None = None,
    yaw_rad: float | None = None,
    time_boot_ms: int = 0,
) -> Any:
    """SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_LOCAL_NED.

    Args:
        target: The vehicle.
        position_ned_m: (3,) north, east, down, m.
        velocity_ned_mps: (3,) velocity feed-forward, m/s; None: position only.
        yaw_rad: Heading, rad (0 = north); None: ignored (the vehicle keeps its heading).
        time_boot_ms: Our time since boot, ms (informational for the vehicle).
    """
    p = np.asarray(position_ned_m, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"position_ned_m must be 3 finite numbers, got {p!r}")
    v = np.zeros(3) if velocity_ned_mps is None else np.asarray(velocity_ned_mps, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"velocity_ned_mps must be 3 finite numbers, got {v!r}")
    if yaw_rad is not None and not math.isfinite(yaw_rad):
        raise ValueError(f"yaw_rad must be finite or None, got {yaw_rad!r}")
    mask = position_type_mask(velocity=velocity_ned_mps is not None, yaw=yaw_rad is not None)
    return mavlink2.MAVLink_set_position_target_local_ned_message(
        int(time_boot_ms) & 0xFFFFFFFF,
        target.system,
        target.component,
        mavlink2.MAV_FRAME_LOCAL_NED,
        mask,
        float(p[0]),
        float(p[1]),
        float(p[2]),
        float(v[0]),
        float(v[1]),
        float(v[2]),
        0.0,
        0.0,
        0.0,
        0.0 if yaw_rad is None else float(yaw_rad),
        0.0,
    )
