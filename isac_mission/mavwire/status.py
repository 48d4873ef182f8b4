"""What a link knows of its vehicle: the `VehicleStatus` snapshot and the `VehicleTelemetry`
record that the link's handlers keep up to date.

Sources: local NED position and velocity (LOCAL_POSITION_NED), heading (ATTITUDE), home altitude
AMSL (GLOBAL_POSITION_INT), the PX4 mode decoded from HEARTBEAT.custom_mode (`px4_mode_name`),
armed (HEARTBEAT base_mode), landed state (EXTENDED_SYS_STATE). Times are on the link's clock, s.
Frames and units: MAV_FRAME_LOCAL_NED (north, east, down), m, m/s, rad; arrays are float64 (3,).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import heartbeat_mode_name
from isac_mission.mavwire.ports import Address
from isac_mission.types import FloatArray

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class VehicleStatus:
    """What the link knows of its vehicle, at `time_s` on the link's clock.

    Attributes:
        time_s: When the snapshot was taken (link clock, s).
        system_id: The vehicle's MAVLink system id (None until heard).
        address: The vehicle's UDP (host, port) (None until heard).
        heartbeat_s: Link-clock time of the last HEARTBEAT, s (None: never).
        lost: No HEARTBEAT for `lost_after_s` (or never heard).
        mode: PX4 mode name (`px4_mode_name`), "unknown" before the first HEARTBEAT.
        custom_mode: Raw HEARTBEAT.custom_mode.
        armed: MAV_MODE_FLAG_SAFETY_ARMED in the last HEARTBEAT.
        landed_state: MAV_LANDED_STATE_* of the last EXTENDED_SYS_STATE (0: undefined).
        position_ned_m: (3,) local NED position, m (None until heard).
        velocity_ned_mps: (3,) local NED velocity, m/s (None until heard).
        position_s: Link-clock time the position was received, s (None until heard).
        yaw_rad: Heading from ATTITUDE, rad (None until heard).
        home_amsl_m: Altitude AMSL of home, m, from GLOBAL_POSITION_INT (alt - relative_alt).
    """

    time_s: float
    system_id: int | None
    address: Address | None
    heartbeat_s: float | None
    lost: bool
    mode: str
    custom_mode: int
    armed: bool
    landed_state: int
    position_ned_m: FloatArray | None
    velocity_ned_mps: FloatArray | None
    position_s: float | None
    yaw_rad: float | None
    home_amsl_m: float | None

    @property
    def landed(self) -> bool:
        """On the ground: landed state ON_GROUND, or (landed state unknown) disarmed."""
        if self.landed_state == mavlink2.MAV_LANDED_STATE_UNDEFINED:
            return not self.armed
        return bool(self.landed_state == mavlink2.MAV_LANDED_STATE_ON_GROUND)

    @property
    def airborne(self) -> bool:
        """Armed and not on the ground."""
        return self.armed and not self.landed

    @property
    def in_air(self) -> bool:
        """Armed and reported in the air (landed state IN_AIR: not taking off, landing or on
        the ground; False while the landed state is unknown)."""
        return self.armed and self.landed_state == mavlink2.MAV_LANDED_STATE_IN_AIR

    @property
    def altitude_m(self) -> float | None:
        """Height above the local origin (-down), m, or None before the first position."""
        return None if self.position_ned_m is None else -float(self.position_ned_m[2])


class VehicleTelemetry:
    """The latest vehicle state heard on one link (handlers for the vehicle's own component).

    Args:
        clock: The link's time source, s.
        name: The link's name, for log messages.
        count_error: Counts bad input by reason, with a detail for the log (the link's).
    """

    def __init__(
        self, clock: Callable[[], float], name: str, count_error: Callable[[str, str], None]
    ) -> None:
        self._clock = clock
        self._name = name
        self._count_error = count_error
        self.heartbeat_s: float | None = None
        """Link-clock time of the last HEARTBEAT, s (None: never)."""
        self.heartbeat_wall_s = 0.0
        """Monotonic wall time of the last HEARTBEAT, s."""
        self.custom_mode = 0
        self.mode = "unknown"
        self.armed = False
        self.landed_state = int(mavlink2.MAV_LANDED_STATE_UNDEFINED)
        self.position_ned_m: FloatArray | None = None
        self.velocity_ned_mps: FloatArray | None = None
        self.position_s: float | None = None
        self.yaw_rad: float | None = None
        self.home_amsl_m: float | None = None

    def on_heartbeat(self, msg: Any) -> None:
        """HEARTBEAT: time, custom mode, armed flag and the PX4 mode name."""
        self.heartbeat_s = self._clock()
        self.heartbeat_wall_s = time.monotonic()
        self.custom_mode = int(msg.custom_mode)
        base_mode = int(msg.base_mode)
        self.armed = bool(base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
        mode = heartbeat_mode_name(int(msg.autopilot), base_mode, self.custom_mode)
        if mode != self.mode:
            log.info("%s: mode %s -> %s", self._name, self.mode, mode)
            self.mode = mode

    def on_local_position_ned(self, msg: Any) -> None:
        """LOCAL_POSITION_NED: position (m) and velocity (m/s); non-finite ones are refused."""
        p = np.array([msg.x, msg.y, msg.z], dtype=float)
        v = np.array([msg.vx, msg.vy, msg.vz], dtype=float)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            self._count_error("non_finite_position", f"{p} {v}")
            return
        self.position_ned_m, self.velocity_ned_mps = p, v
        self.position_s = self._clock()

    def on_global_position_int(self, msg: Any) -> None:
        """GLOBAL_POSITION_INT: home altitude AMSL = alt - relative_alt (mm on the wire), m."""
        self.home_amsl_m = (int(msg.alt) - int(msg.relative_alt)) / 1000.0

    def on_extended_sys_state(self, msg: Any) -> None:
        """EXTENDED_SYS_STATE: the landed state."""
        self.landed_state = int(msg.landed_state)

    def on_attitude(self, msg: Any) -> None:
        """ATTITUDE: the heading, rad (a non-finite yaw is ignored)."""
        yaw = float(msg.yaw)
        if math.isfinite(yaw):
            self.yaw_rad = yaw

    def snapshot(self, system_id: int | None, address: Address | None, lost: bool) -> VehicleStatus:
        """A `VehicleStatus` now (copies of the arrays)."""
        p, v = self.position_ned_m, self.velocity_ned_mps
        return VehicleStatus(
            time_s=self._clock(),
            system_id=system_id,
            address=address,
            heartbeat_s=self.heartbeat_s,
            lost=lost,
            mode=self.mode,
            custom_mode=self.custom_mode,
            armed=self.armed,
            landed_state=self.landed_state,
            position_ned_m=None if p is None else p.copy(),
            velocity_ned_mps=None if v is None else v.copy(),
            position_s=self.position_s,
            yaw_rad=self.yaw_rad,
            home_amsl_m=self.home_amsl_m,
        )
