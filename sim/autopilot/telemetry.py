"""Telemetry of the simulated vehicle: the messages it streams and answers with, built from its
flight logic (pure builders: no socket).

HEARTBEAT (PX4, custom mode of `FlightMode`), SYS_STATUS (every sensor present, enabled and
healthy but the battery from its critical level on, pre-arm checks passed; the battery's
voltage, current and remaining %, as BATTERY_STATUS has them), EXTENDED_SYS_STATE (landed
state), ATTITUDE (roll and pitch from the horizontal acceleration), LOCAL_POSITION_NED,
GLOBAL_POSITION_INT, GPS_RAW_INT, GPS_GLOBAL_ORIGIN, HOME_POSITION, BATTERY_STATUS, VFR_HUD,
MISSION_CURRENT and AUTOPILOT_VERSION (which advertises what the vehicle does: MISSION_INT and
MISSION_FLOAT, COMMAND_INT, PARAM_FLOAT with bytewise encoding, SET_POSITION_TARGET_LOCAL_NED,
MAVLink 2). Geodetic positions come from
`isac_mission.frames` (flat earth around the scenario origin `geo_origin`). Units on the wire as
MAVLink has them (degE7, mm, cm/s, cdeg, us, ms).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from isac_mission.frames import GeoPoint, ned_to_geodetic
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from isac_mission.types import FloatArray
from sim.autopilot.battery import BatteryWarning
from sim.autopilot.flight import FlightLogic
from sim.autopilot.settings import AutopilotSettings

GRAVITY_MPS2 = 9.80665


def battery_percent(remaining: float) -> int:
    """Remaining charge as MAVLink's integer percent (rounded up, as PX4 does)."""
    return min(100, max(0, math.ceil(remaining * 100.0 - 1e-9)))


def default_intervals(s: AutopilotSettings) -> dict[int, float]:
    """The streams a link starts with: message id -> period, s (simulation time)."""
    fast, status = 1.0 / s.telemetry_rate_hz, 1.0 / s.status_rate_hz
    return {
        mavlink2.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
        mavlink2.MAVLINK_MSG_ID_SYS_STATUS: status,
        mavlink2.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: status,
        mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT: status,
        mavlink2.MAVLINK_MSG_ID_ATTITUDE: fast,
        mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED: fast,
        mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: fast,
        mavlink2.MAVLINK_MSG_ID_HOME_POSITION: 1.0 / s.home_rate_hz,
        mavlink2.MAVLINK_MSG_ID_BATTERY_STATUS: status,
        mavlink2.MAVLINK_MSG_ID_VFR_HUD: 1.0 / s.vfr_hud_rate_hz,
        mavlink2.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    }


class Telemetry:
    """The message builders of one vehicle, reading its flight logic at build time."""

    def __init__(self, flight: FlightLogic) -> None:
        self._flight = flight
        self.builders: dict[int, Callable[[], Any]] = {
            mavlink2.MAVLINK_MSG_ID_HEARTBEAT: self.heartbeat,
            mavlink2.MAVLINK_MSG_ID_SYS_STATUS: self.sys_status,
            mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT: self.gps_raw_int,
            mavlink2.MAVLINK_MSG_ID_ATTITUDE: self.attitude,
            mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self.local_position_ned,
            mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self.global_position_int,
            mavlink2.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: self.gps_global_origin,
            mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self.autopilot_version,
            mavlink2.MAVLINK_MSG_ID_HOME_POSITION: self.home_position,
            mavlink2.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self.extended_sys_state,
            mavlink2.MAVLINK_MSG_ID_BATTERY_STATUS: self.battery_status,
            mavlink2.MAVLINK_MSG_ID_VFR_HUD: self.vfr_hud,
            mavlink2.MAVLINK_MSG_ID_MISSION_CURRENT: self.mission_current,
        }
        """Message id -> builder, for the streams and MAV_CMD_REQUEST_MESSAGE."""

    def _time_boot_ms(self) -> int:
        return round(self._flight.now_s * 1000.0) & 0xFFFFFFFF

    def _geodetic(self, ned: FloatArray) -> GeoPoint:
        f = self._flight
        return ned_to_geodetic(ned, f.origin_xy_m, f.settings.geo_origin, f.limits.ground_down_m)

    def heartbeat(self) -> Any:
        base = (
            mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | mavlink2.MAV_MODE_FLAG_AUTO_ENABLED
            | mavlink2.MAV_MODE_FLAG_GUIDED_ENABLED
            | mavlink2.MAV_MODE_FLAG_STABILIZE_ENABLED
        )
        if self._flight.armed:
            base |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink2.MAV_STATE_ACTIVE if self._flight.armed else mavlink2.MAV_STATE_STANDBY
        return mavlink2.MAVLink_heartbeat_message(
            mavlink2.MAV_TYPE_QUADROTOR,
            mavlink2.MAV_AUTOPILOT_PX4,
            base,
            self._flight.mode.px4_custom_mode,
            status,
            3,
        )

    def sys_status(self) -> Any:
        sensors = (
            mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO
            | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | mavlink2.MAV_SYS_STATUS_SENSOR_3D_MAG
            | mavlink2.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | mavlink2.MAV_SYS_STATUS_SENSOR_GPS
            | mavlink2.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | mavlink2.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
            | mavlink2.MAV_SYS_STATUS_SENSOR_YAW_POSITION
            | mavlink2.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
            | mavlink2.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
            | mavlink2.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | mavlink2.MAV_SYS_STATUS_AHRS
            | mavlink2.MAV_SYS_STATUS_SENSOR_BATTERY
            | mavlink2.MAV_SYS_STATUS_PREARM_CHECK
        )
        b = self._flight.battery
        health = sensors
        if b.warning >= BatteryWarning.CRITICAL:
            health &= ~mavlink2.MAV_SYS_STATUS_SENSOR_BATTERY
        return mavlink2.MAVLink_sys_status_message(
            sensors,
            sensors,
            health,
            150,
            round(b.voltage_v * 1000.0),
            round(b.current_a * 100.0),
            battery_percent(b.remaining),
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
            0,
        )

    def battery_status(self) -> Any:
        """BATTERY_STATUS of battery 0: cell voltages, current, charge and energy drawn,
        remaining %, time to empty and the charge state of PX4's warning level."""
        b = self._flight.battery
        cells = b.settings.cells
        cell_mv = min(65534, round(1000.0 * b.voltage_v / cells))
        voltages = [cell_mv] * min(cells, 10) + [65535] * (10 - min(cells, 10))
        ext = [cell_mv if i + 10 < cells else 0 for i in range(4)]
        return mavlink2.MAVLink_battery_status_message(
            0,
            mavlink2.MAV_BATTERY_FUNCTION_ALL,
            mavlink2.MAV_BATTERY_TYPE_LIPO,
            32767,
            voltages,
            round(b.current_a * 100.0),
            round(b.charge_drawn_mah),
            round(b.energy_drawn_wh * 36.0),
            battery_percent(b.remaining),
            min(2**31 - 1, round(b.time_remaining_s)),
            int(b.warning) + 1,
            ext,
        )

    def vfr_hud(self) -> Any:
        """VFR_HUD: air speed = ground speed (no wind), heading, throttle (motor power over
        twice the hover power, %), altitude AMSL and climb rate."""
        f = self._flight
        v = f.vehicle.velocity_ned_mps
        speed = float(np.hypot(v[0], v[1]))
        heading = round(math.degrees(f.vehicle.yaw_rad)) % 360
        b = f.battery
        motor_w = b.power_w - b.settings.idle_power_w if f.armed else 0.0
        throttle = min(100, max(0, round(50.0 * motor_w / b.settings.hover_power_w)))
        alt = self._geodetic(f.vehicle.position_ned_m).alt_amsl_m
        return mavlink2.MAVLink_vfr_hud_message(speed, speed, heading, throttle, alt, -float(v[2]))

    def mission_current(self) -> Any:
        """MISSION_CURRENT: the current item, the plan's size and the mission state."""
        f = self._flight
        m = f.mission
        if not m.items:
            state = mavlink2.MISSION_STATE_NO_MISSION
        elif m.finished:
            state = mavlink2.MISSION_STATE_COMPLETE
        elif f.mode is FlightMode.MISSION:
            state = mavlink2.MISSION_STATE_ACTIVE
        else:
            state = mavlink2.MISSION_STATE_NOT_STARTED
        in_mission = 1 if f.mode is FlightMode.MISSION else 2
        return mavlink2.MAVLink_mission_current_message(m.current, len(m.items), state, in_mission)

    def extended_sys_state(self) -> Any:
        if self._flight.landed:
            landed = mavlink2.MAV_LANDED_STATE_ON_GROUND
        elif self._flight.mode is FlightMode.TAKEOFF:
            landed = mavlink2.MAV_LANDED_STATE_TAKEOFF
        elif self._flight.landing():
            landed = mavlink2.MAV_LANDED_STATE_LANDING
        else:
            landed = mavlink2.MAV_LANDED_STATE_IN_AIR
        return mavlink2.MAVLink_extended_sys_state_message(mavlink2.MAV_VTOL_STATE_MC, landed)

    def attitude(self) -> Any:
        a = self._flight.accel_ned_mps2
        yaw = self._flight.vehicle.yaw_rad
        a_fwd = a[0] * math.cos(yaw) + a[1] * math.sin(yaw)
        a_right = -a[0] * math.sin(yaw) + a[1] * math.cos(yaw)
        pitch = -math.atan2(a_fwd, GRAVITY_MPS2)
        roll = math.atan2(a_right, GRAVITY_MPS2)
        return mavlink2.MAVLink_attitude_message(
            self._time_boot_ms(), roll, pitch, yaw, 0.0, 0.0, self._flight.yaw_rate_rps
        )

    def local_position_ned(self) -> Any:
        p, v = self._flight.vehicle.position_ned_m, self._flight.vehicle.velocity_ned_mps
        return mavlink2.MAVLink_local_position_ned_message(
            self._time_boot_ms(), p[0], p[1], p[2], v[0], v[1], v[2]
        )

    def global_position_int(self) -> Any:
        p, v = self._flight.vehicle.position_ned_m, self._flight.vehicle.velocity_ned_mps
        geo = self._geodetic(p)
        rel_alt_m = float(self._flight.home_ned[2] - p[2])
        hdg = round(math.degrees(self._flight.vehicle.yaw_rad) * 100.0) % 36000
        return mavlink2.MAVLink_global_position_int_message(
            self._time_boot_ms(),
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            round(rel_alt_m * 1000.0),
            round(v[0] * 100.0),
            round(v[1] * 100.0),
            round(v[2] * 100.0),
            hdg,
        )

    def gps_raw_int(self) -> Any:
        p, v = self._flight.vehicle.position_ned_m, self._flight.vehicle.velocity_ned_mps
        geo = self._geodetic(p)
        speed = float(np.hypot(v[0], v[1]))
        cog = round(math.degrees(math.atan2(v[1], v[0])) * 100.0) % 36000 if speed > 0.1 else 65535
        return mavlink2.MAVLink_gps_raw_int_message(
            round(self._flight.now_s * 1e6),
            mavlink2.GPS_FIX_TYPE_3D_FIX,
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            70,
            90,
            round(speed * 100.0),
            cog,
            14,
        )

    def gps_global_origin(self) -> Any:
        geo = self._geodetic(np.array([0.0, 0.0, self._flight.limits.ground_down_m]))
        return mavlink2.MAVLink_gps_global_origin_message(
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            round(self._flight.now_s * 1e6),
        )

    def home_position(self) -> Any:
        h = self._flight.home_ned
        geo = self._geodetic(h)
        return mavlink2.MAVLink_home_position_message(
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            h[0],
            h[1],
            h[2],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            round(self._flight.now_s * 1e6),
        )

    def autopilot_version(self) -> Any:
        caps = (
            mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            | mavlink2.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | mavlink2.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        )
        version = (1 << 24) | (15 << 16) | (0 << 8) | 255  # "v1.15.0, official"
        return mavlink2.MAVLink_autopilot_version_message(
            caps,
            version,
            0,
            0,
            0,
            [0] * 8,
            [0] * 8,
            [0] * 8,
            0,
            0,
            0x1500 + self._flight.system_id,
            [0] * 18,
        )
