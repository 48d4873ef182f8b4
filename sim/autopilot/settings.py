"""Settings of one simulated vehicle, validated with pydantic; a bad value raises ConfigError.

Units: m, s, Hz, m/s; ports are UDP on 127.0.0.1 (docs/service.md, "The simulated vehicles").
"""

from __future__ import annotations

import math
from typing import ClassVar, Literal

from pydantic import Field, InstanceOf, model_validator

from isac_mission.config import MavlinkSigningKey
from isac_mission.config.validation import Settings
from isac_mission.errors import ConfigError
from isac_mission.frames import PX4_SITL_ORIGIN, GeoPoint
from isac_mission.mavwire.ports import (
    GCS_LOCAL_BASE_PORT,
    GCS_PORT,
    OFFBOARD_BASE_PORT,
    OFFBOARD_LOCAL_BASE_PORT,
)
from sim.autopilot.battery import BatterySettings
from sim.vehicle import VehicleLimits

LossAction = Literal["none", "hold", "land"]
"""What the vehicle does when the ground station's heartbeats stop (PX4 NAV_DLL_ACT)."""
LowBatteryAction = Literal["warn", "return", "land", "return_then_land"]
"""PX4 COM_LOW_BAT_ACT: 0 warn only, 1 Return, 2 Land, 3 Return at critical and Land at
emergency."""

_POSITIVE = (
    "takeoff_alt_m",
    "land_speed_mps",
    "offboard_min_rate_hz",
    "offboard_loss_timeout_s",
    "gcs_loss_timeout_s",
    "telemetry_rate_hz",
    "status_rate_hz",
    "home_rate_hz",
    "max_altitude_m",
    "cruise_speed_mps",
    "rtl_return_alt_m",
    "rtl_descend_alt_m",
    "acceptance_radius_m",
    "altitude_acceptance_m",
    "vfr_hud_rate_hz",
)


class AutopilotSettings(Settings):
    """Configuration of one simulated vehicle. Units: m, s, Hz, m/s; ports are UDP on 127.0.0.1.

    Attributes:
        index: 0-based vehicle index m; MAVLink system id m + 1.
        offboard_port: Where the offboard client listens; None = 14540 + index (PX4 SITL).
        gcs_port: Where the ground station listens; None = 14550 (PX4 SITL: one port for the
            whole fleet).
        bind_port: Local port of the offboard link; None = 14580 + index (PX4 SITL), 0 =
            ephemeral.
        gcs_bind_port: Local port of the GCS link; None = 18570 + index (PX4 SITL), 0 =
            ephemeral.
        geo_origin: Geodetic position of the scenario origin (0, 0) on the ground.
        local_origin_xy_m: Scenario-plane (x east, y north) origin of the local NED frame.
        spawn_xy_m: Scenario-plane start position on the ground; None = the local origin.
        spawn_yaw_rad: Initial heading, rad (0 = north).
        takeoff_alt_m: MIS_TAKEOFF_ALT, altitude above ground of a takeoff without altitude.
        limits: Kinematic limits of the airframe.
        land_speed_mps: MPC_LAND_SPEED, descent rate of LAND near the ground.
        land_slow_below_m: Below this height LAND descends at `land_speed_mps`, above it at the
            maximum descent rate (PX4 MPC_LAND_ALT1).
        offboard_min_rate_hz: Setpoint rate (simulation time) needed to enter OFFBOARD.
        offboard_loss_timeout_s: COM_OF_LOSS_T.
        offboard_loss_action: COM_OBL_RC_ACT: "hold" or "land".
        gcs_loss_timeout_s: COM_DL_LOSS_T.
        gcs_loss_action: NAV_DLL_ACT: "none", "hold" or "land".
        disarm_after_land_s: COM_DISARM_LAND; <= 0 disables auto-disarm after landing.
        disarm_preflight_s: COM_DISARM_PRFLT; <= 0 disables auto-disarm before takeoff.
        telemetry_rate_hz: Rate of ATTITUDE, LOCAL_POSITION_NED and GLOBAL_POSITION_INT.
        status_rate_hz: Rate of SYS_STATUS, EXTENDED_SYS_STATE and GPS_RAW_INT.
        home_rate_hz: Rate of HOME_POSITION.
        heartbeat_keepalive_wall_s: Wall-clock heartbeat period when simulation time stalls;
            None disables it.
        area_min_xy_m: Scenario-plane lower corner of the allowed area (geofence).
        area_max_xy_m: Scenario-plane upper corner of the allowed area.
        min_altitude_m: Lowest altitude a position setpoint may ask for (higher ones clamped up).
        max_altitude_m: Highest altitude a position setpoint may ask for.
        signing: MAVLink 2 signing key of every link; None = no signing (accept unsigned).
        cruise_speed_mps: MPC_XY_CRUISE, horizontal speed of RTL, missions and DO_REPOSITION.
        rtl_return_alt_m: RTL_RETURN_ALT, return altitude above home.
        rtl_descend_alt_m: RTL_DESCEND_ALT, altitude over home before landing.
        rtl_land_delay_s: RTL_LAND_DELAY, hover over home before landing (< 0: for ever).
        acceptance_radius_m: NAV_ACC_RAD, a mission waypoint's default acceptance radius.
        altitude_acceptance_m: NAV_MC_ALT_RAD, a mission item's altitude acceptance.
        battery: The energy model (`battery.BatterySettings`).
        battery_low_thr: BAT_LOW_THR, remaining fraction of the low-battery warning.
        battery_crit_thr: BAT_CRIT_THR, remaining fraction of the critical level.
        battery_emergen_thr: BAT_EMERGEN_THR, remaining fraction of the emergency level.
        low_battery_action: COM_LOW_BAT_ACT (`LowBatteryAction`).
        battery_action_delay_s: COM_BAT_ACT_T, delay between a battery level and its action.
        vfr_hud_rate_hz: Rate of VFR_HUD (BATTERY_STATUS streams at `status_rate_hz`).
        serial_device: A serial device (e.g. one end of a pseudo-terminal pair) the vehicle also
            speaks MAVLink on, as PX4 on a TELEM port; None = UDP links only.
        serial_baud: Its rate (raw 8N1).
    """

    settings_name: ClassVar[str] = "AutopilotSettings"

    index: int = 0
    offboard_port: int | None = None
    gcs_port: int | None = None
    bind_port: int | None = None
    gcs_bind_port: int | None = None
    geo_origin: InstanceOf[GeoPoint] = PX4_SITL_ORIGIN
    local_origin_xy_m: tuple[float, float] = (0.0, 0.0)
    spawn_xy_m: tuple[float, float] | None = None
    spawn_yaw_rad: float = 0.0
    takeoff_alt_m: float = 2.5
    limits: InstanceOf[VehicleLimits] = Field(default_factory=VehicleLimits)
    land_speed_mps: float = 0.7
    land_slow_below_m: float = 10.0
    offboard_min_rate_hz: float = 2.0
    offboard_loss_timeout_s: float = 1.0
    offboard_loss_action: Literal["hold", "land"] = "hold"
    gcs_loss_timeout_s: float = 10.0
    gcs_loss_action: LossAction = "hold"
    disarm_after_land_s: float = 2.0
    disarm_preflight_s: float = 10.0
    telemetry_rate_hz: float = 20.0
    status_rate_hz: float = 2.0
    home_rate_hz: float = 0.5
    heartbeat_keepalive_wall_s: float | None = 1.0
    area_min_xy_m: tuple[float, float] = (-10_000.0, -10_000.0)
    area_max_xy_m: tuple[float, float] = (10_000.0, 10_000.0)
    min_altitude_m: float = 2.0
    max_altitude_m: float = 500.0
    signing: InstanceOf[MavlinkSigningKey] | None = None
    cruise_speed_mps: float = 5.0
    rtl_return_alt_m: float = 60.0
    rtl_descend_alt_m: float = 30.0
    rtl_land_delay_s: float = 0.0
    acceptance_radius_m: float = 2.0
    altitude_acceptance_m: float = 0.8
    battery: BatterySettings = Field(default_factory=BatterySettings)
    battery_low_thr: float = 0.15
    battery_crit_thr: float = 0.07
    battery_emergen_thr: float = 0.05
    low_battery_action: LowBatteryAction = "return_then_land"
    battery_action_delay_s: float = 5.0
    vfr_hud_rate_hz: float = 4.0
    serial_device: str | None = None
    serial_baud: int = 57600

    @model_validator(mode="after")
    def _check_values(self) -> AutopilotSettings:
        """Every out-of-range value, one `AutopilotSettings: ...` line each (ConfigError)."""
        problems: list[str] = []
        if not 0 <= self.index <= 253:
            problems.append(f"index must be in [0, 253] (got {self.index})")
        for name in ("offboard_port", "gcs_port", "bind_port", "gcs_bind_port"):
            port = getattr(self, name)
            if port is not None and not 0 <= port <= 65535:
                problems.append(f"{name} must be a UDP port (got {port})")
        for name in _POSITIVE:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                problems.append(f"{name} must be finite and > 0 (got {value})")
        if not (0.0 <= self.min_altitude_m < self.max_altitude_m):
            problems.append(
                f"min_altitude_m must be in [0, max_altitude_m) (got {self.min_altitude_m})"
            )
        if any(lo >= hi for lo, hi in zip(self.area_min_xy_m, self.area_max_xy_m, strict=True)):
            problems.append(
                f"area_min_xy_m {self.area_min_xy_m} must be below area_max_xy_m {self.area_max_xy_m}"
            )
        thresholds = (self.battery_emergen_thr, self.battery_crit_thr, self.battery_low_thr)
        if not 0.0 <= thresholds[0] <= thresholds[1] <= thresholds[2] < 1.0:
            problems.append(
                "battery thresholds must satisfy 0 <= battery_emergen_thr <= battery_crit_thr"
                f" <= battery_low_thr < 1 (got {thresholds[0]}, {thresholds[1]}, {thresholds[2]})"
            )
        if not (math.isfinite(self.battery_action_delay_s) and self.battery_action_delay_s >= 0):
            problems.append(
                f"battery_action_delay_s must be finite and >= 0 (got {self.battery_action_delay_s})"
            )
        if self.serial_device is not None and not self.serial_device.startswith("/"):
            problems.append(f"serial_device must be a device path (got {self.serial_device!r})")
        if self.serial_baud <= 0:
            problems.append(f"serial_baud must be > 0 (got {self.serial_baud})")
        if self.heartbeat_keepalive_wall_s is not None and not self.heartbeat_keepalive_wall_s > 0:
            problems.append("heartbeat_keepalive_wall_s must be > 0 or None")
        if problems:
            raise ConfigError("\n".join(f"AutopilotSettings: {p}" for p in problems))
        return self

    @property
    def system_id(self) -> int:
        """MAVLink system id: index + 1."""
        return self.index + 1

    @property
    def offboard_dest_port(self) -> int:
        """The offboard client's port (14540 + index unless configured)."""
        return OFFBOARD_BASE_PORT + self.index if self.offboard_port is None else self.offboard_port

    @property
    def gcs_dest_port(self) -> int:
        """The ground station's port (14550, for every vehicle, unless configured)."""
        return GCS_PORT if self.gcs_port is None else self.gcs_port

    @property
    def offboard_local_port(self) -> int:
        """The offboard link's local port (14580 + index unless configured; 0 = ephemeral)."""
        return OFFBOARD_LOCAL_BASE_PORT + self.index if self.bind_port is None else self.bind_port

    @property
    def gcs_local_port(self) -> int:
        """The GCS link's local port (18570 + index unless configured; 0 = ephemeral)."""
        return (
            GCS_LOCAL_BASE_PORT + self.index if self.gcs_bind_port is None else self.gcs_bind_port
        )
