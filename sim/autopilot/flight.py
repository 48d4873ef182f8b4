"""The flight logic of a PX4-like multirotor around the kinematic core (pure: no I/O).

Modes HOLD (AUTO.LOITER), TAKEOFF (AUTO.TAKEOFF), LAND (AUTO.LAND) and OFFBOARD; `armed` and
`landed` complete the state (landed/disarmed, armed on the ground, in the air). The PX4 rules a
ground service must respect are kept:

- OFFBOARD is DENIED unless setpoints are streaming (the last one younger than
  1 / `offboard_min_rate_hz`, 0.5 s); when they stop for COM_OF_LOSS_T the vehicle takes the
  offboard-loss action (HOLD or LAND) and says so (`say`, a STATUSTEXT);
- after a client HEARTBEAT has been heard, silence for COM_DL_LOSS_T makes an airborne vehicle take
  the datalink-loss action (NAV_DLL_ACT: none, HOLD or LAND);
- the vehicle disarms COM_DISARM_LAND after touching down and COM_DISARM_PRFLT after arming
  without taking off.

Everything runs on simulation time: `step(now_s, dt_s)` integrates the vehicle (`sim.vehicle`),
checks the timeouts against `now_s` and runs the land detector. Frames: local NED (north, east,
down, m) around the scenario-plane point `local_origin_xy_m` (`isac_mission.frames`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from isac_mission.frames import ned_to_scenario_xy, scenario_to_ned
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from isac_mission.types import FloatArray
from sim.autopilot.params import LIMIT_FIELDS, Param
from sim.autopilot.settings import AutopilotSettings
from sim.vehicle import Setpoint, VehicleState, stopping_point, wrap_pi
from sim.vehicle import step as vehicle_step

logger = logging.getLogger(__name__)

_LANDED_ALT_M = 0.05
_AIRBORNE_ALT_M = 0.1
_TAKEOFF_DONE_M = 0.2

RESULT_ACCEPTED: int = mavlink2.MAV_RESULT_ACCEPTED
RESULT_DENIED: int = mavlink2.MAV_RESULT_DENIED
RESULT_UNSUPPORTED: int = mavlink2.MAV_RESULT_UNSUPPORTED

Say = Callable[[int, str], None]
"""Tells the ground a STATUSTEXT: (MAV_SEVERITY_*, text)."""


@dataclass(frozen=True)
class AutopilotState:
    """A snapshot of the vehicle, as the world and tests see it.

    Attributes:
        time_s: Simulation time of the snapshot, s.
        position_ned_m: (3,) local NED position, m.
        velocity_ned_mps: (3,) local NED velocity, m/s.
        yaw_rad: Heading, rad.
        position_xy_m: (2,) scenario-plane position (x east, y north), m.
        altitude_m: Height above the ground, m.
        mode: Current flight mode.
        armed: Motors armed.
        landed: On the ground (land detector).
        gcs_lost: No client heartbeat for COM_DL_LOSS_T (after one was heard).
    """

    time_s: float
    position_ned_m: FloatArray
    velocity_ned_mps: FloatArray
    yaw_rad: float
    position_xy_m: FloatArray
    altitude_m: float
    mode: FlightMode
    armed: bool
    landed: bool
    gcs_lost: bool


class FlightLogic:
    """One vehicle's modes, failsafes, land detector and kinematics (see the module docstring).

    Args:
        settings: The vehicle's settings.
        params: The live parameter table (`params.make_params`); read at every use.
        say: Sends a STATUSTEXT to the ground (failsafes announce themselves).
    """

    def __init__(self, settings: AutopilotSettings, params: dict[str, Param], say: Say) -> None:
        self.settings = settings
        self.params = params
        self._say = say
        self.system_id = settings.system_id
        self.origin_xy_m = np.array(settings.local_origin_xy_m, dtype=np.float64)
        """Scenario-plane origin (2,) of the local NED frame, m."""
        spawn_xy = np.array(
            settings.spawn_xy_m if settings.spawn_xy_m is not None else settings.local_origin_xy_m,
            dtype=np.float64,
        )
        self.vehicle = VehicleState(
            position_ned_m=scenario_to_ned(
                spawn_xy, -settings.limits.ground_down_m, self.origin_xy_m
            ),
            yaw_rad=wrap_pi(settings.spawn_yaw_rad),
        )
        self.limits = settings.limits
        self.now_s = 0.0
        self.mode = FlightMode.HOLD
        self.armed = False
        self.landed = True
        self._armed_at_s = 0.0
        self._landed_at_s: float | None = None
        self._hold_ned = self.vehicle.position_ned_m.copy()
        self._land_xy_ned = self.vehicle.position_ned_m[:2].copy()
        self._takeoff_ned = self.vehicle.position_ned_m.copy()
        self.home_ned = self.vehicle.position_ned_m.copy()
        """Where the vehicle armed last (local NED (3,), m)."""
        self.offboard_sp: Setpoint | None = None
        self.last_setpoint_s = -math.inf
        self._last_client_heartbeat_s: float | None = None
        self.gcs_lost = False
        self.accel_ned_mps2 = np.zeros(3)
        """Acceleration over the last step, NED (3,), m/s^2."""
        self.yaw_rate_rps = 0.0
        self.state = self.snapshot()
        """The latest snapshot (replaced after every step and every state change)."""

    def param(self, name: str) -> float:
        """The value in force of parameter `name`."""
        return self.params[name].value

    def apply_param(self, name: str) -> None:
        """Push a changed parameter into the live limits."""
        if name in LIMIT_FIELDS:
            self.limits = replace(self.limits, **{LIMIT_FIELDS[name]: self.params[name].value})

    def step(self, now_s: float, dt_s: float) -> None:
        """Advance to simulation time `now_s` (s) by `dt_s` (s): failsafes, physics, land
        detector, then a new snapshot."""
        self.now_s = now_s
        self._check_failsafes()
        v0 = self.vehicle
        sp = self._control_setpoint()
        if sp is not None:
            self.vehicle = vehicle_step(v0, sp, self.limits, dt_s)
        v1 = self.vehicle
        self.accel_ned_mps2 = (v1.velocity_ned_mps - v0.velocity_ned_mps) / dt_s
        self.yaw_rate_rps = wrap_pi(v1.yaw_rad - v0.yaw_rad) / dt_s
        self._update_land_detector()
        self.state = self.snapshot()

    def height_m(self) -> float:
        """Height above the ground, m."""
        return float(self.limits.ground_down_m - self.vehicle.position_ned_m[2])

    def _control_setpoint(self) -> Setpoint | None:
        """What the vehicle tracks this step; None = motors off (stay put)."""
        if not self.armed:
            return None
        mode = self.mode
        if self.landed and mode in (FlightMode.HOLD, FlightMode.LAND):
            return None
        if mode is FlightMode.TAKEOFF:
            return Setpoint.hold_at(self._takeoff_ned)
        if mode is FlightMode.HOLD:
            return Setpoint.hold_at(self._hold_ned)
        if mode is FlightMode.LAND:
            rate = (
                self.limits.max_descent_rate_mps
                if self.height_m() > self.settings.land_slow_below_m
                else self.param("MPC_LAND_SPEED")
            )
            return Setpoint(
                position_ned_m=np.array([self._land_xy_ned[0], self._land_xy_ned[1], math.nan]),
                velocity_ned_mps=np.array([0.0, 0.0, rate]),
            )
        return self.offboard_sp

    def set_mode(self, mode: FlightMode, reason: str) -> None:
        """Switch to `mode` (HOLD holds at the stopping point, LAND lands below it)."""
        if mode is FlightMode.HOLD:
            self._hold_ned = stopping_point(self.vehicle, self.limits)
        elif mode is FlightMode.LAND:
            self._land_xy_ned = stopping_point(self.vehicle, self.limits)[:2]
        if mode is not self.mode:
            logger.info(
                "vehicle %d: mode %s -> %s (%s)",
                self.system_id,
                self.mode.value,
                mode.value,
                reason,
            )
        self.mode = mode
        self.state = self.snapshot()

    def setpoint_stream_ok(self) -> bool:
        """True when the last setpoint is younger than 1 / offboard_min_rate_hz (sim time).

        PX4 only asks that the last setpoint be younger than COM_OF_LOSS_T; asking for the
        period of a `offboard_min_rate_hz` stream (0.5 s at 2 Hz) is the stricter reading of
        "setpoints must already stream at > 2 Hz", and still lets MAVSDK's usual
        `set_position_ned(); start()` through, since MAVSDK streams from the first set call.
        """
        age_s = self.now_s - self.last_setpoint_s
        return age_s <= 1.0 / self.settings.offboard_min_rate_hz

    def set_offboard_setpoint(self, setpoint: Setpoint) -> None:
        """A new offboard setpoint, received now."""
        self.offboard_sp = setpoint
        self.last_setpoint_s = self.now_s

    def client_heartbeat(self, link_name: str) -> None:
        """A client HEARTBEAT was heard on link `link_name` (restores a lost GCS)."""
        if self.gcs_lost:
            logger.info(
                "vehicle %d: client heartbeat regained on %s link", self.system_id, link_name
            )
            self.gcs_lost = False
            self.state = self.snapshot()
        self._last_client_heartbeat_s = self.now_s

    def _check_failsafes(self) -> None:
        self._check_offboard_loss()
        self._check_datalink_loss()
        self._check_auto_disarm()

    def _check_offboard_loss(self) -> None:
        if self.mode is not FlightMode.OFFBOARD:
            return
        if self.now_s - self.last_setpoint_s <= self.param("COM_OF_LOSS_T"):
            return
        lands = self.param("COM_OBL_RC_ACT") == 4
        action = FlightMode.LAND if lands else FlightMode.HOLD
        logger.warning("vehicle %d: offboard setpoints lost, %s", self.system_id, action.value)
        self.set_mode(action, "offboard loss")
        self._say(mavlink2.MAV_SEVERITY_WARNING, f"Offboard lost: {action.value}")

    def _check_datalink_loss(self) -> None:
        last = self._last_client_heartbeat_s
        if last is None or self.gcs_lost:
            return
        silent_s = self.now_s - last
        if silent_s <= self.param("COM_DL_LOSS_T"):
            return
        self.gcs_lost = True
        act = int(self.param("NAV_DLL_ACT"))
        action = {1: FlightMode.HOLD, 3: FlightMode.LAND}.get(act)
        logger.warning(
            "vehicle %d: no client heartbeat for %.1f s, action %s",
            self.system_id,
            silent_s,
            action.value if action else "none",
        )
        airborne = self.armed and not self.landed
        if action is not None and airborne and self.mode not in (FlightMode.LAND, action):
            self.set_mode(action, "datalink loss")
        self._say(mavlink2.MAV_SEVERITY_CRITICAL, "Connection to ground station lost")
        self.state = self.snapshot()

    def _check_auto_disarm(self) -> None:
        if not (self.armed and self.landed):
            return
        now = self.now_s
        if self._landed_at_s is not None:
            delay = self.param("COM_DISARM_LAND")
            if delay > 0 and now - self._landed_at_s >= delay:
                self.disarm("landed")
        else:
            delay = self.param("COM_DISARM_PRFLT")
            if delay > 0 and now - self._armed_at_s >= delay:
                self.disarm("no takeoff after arming")

    def _update_land_detector(self) -> None:
        height = self.height_m()
        v_down = float(self.vehicle.velocity_ned_mps[2])
        if self.landed and self.armed and height > _AIRBORNE_ALT_M:
            self.landed = False
            self._landed_at_s = None
            logger.info("vehicle %d: airborne", self.system_id)
        elif not self.landed and height < _LANDED_ALT_M and v_down >= -0.05:
            self.landed = True
            self._landed_at_s = self.now_s
            logger.info("vehicle %d: landed", self.system_id)
        to_go_m = abs(float(self._takeoff_ned[2] - self.vehicle.position_ned_m[2]))
        if self.mode is FlightMode.TAKEOFF and not self.landed and to_go_m < _TAKEOFF_DONE_M:
            self.set_mode(FlightMode.HOLD, "takeoff complete")

    def arm(self) -> int:
        """Arm (on the ground only); a MAV_RESULT."""
        if self.armed:
            return RESULT_ACCEPTED
        if not self.landed:
            return RESULT_DENIED
        self.armed = True
        self._armed_at_s = self.now_s
        self._landed_at_s = None
        self.home_ned = self.vehicle.position_ned_m.copy()
        if self.mode in (FlightMode.LAND, FlightMode.TAKEOFF):
            self.set_mode(FlightMode.HOLD, "armed")
        logger.info("vehicle %d: armed", self.system_id)
        self.state = self.snapshot()
        return RESULT_ACCEPTED

    def disarm(self, reason: str) -> int:
        """Disarm (on the ground only); a MAV_RESULT."""
        if not self.armed:
            return RESULT_ACCEPTED
        if not self.landed:
            return RESULT_DENIED
        self.armed = False
        self.vehicle = replace(self.vehicle, velocity_ned_mps=np.zeros(3))
        logger.info("vehicle %d: disarmed (%s)", self.system_id, reason)
        self.state = self.snapshot()
        return RESULT_ACCEPTED

    def takeoff(self, alt_amsl_m: float) -> int:
        """Take off to `alt_amsl_m` (NaN: MIS_TAKEOFF_ALT above home), clamped to the altitude
        band; a MAV_RESULT."""
        if not self.armed:
            return RESULT_DENIED
        home_amsl = self.settings.geo_origin.alt_amsl_m + float(
            self.limits.ground_down_m - self.home_ned[2]
        )
        height = (
            alt_amsl_m - home_amsl if math.isfinite(alt_amsl_m) else self.param("MIS_TAKEOFF_ALT")
        )
        height = min(max(height, self.settings.min_altitude_m), self.settings.max_altitude_m)
        xy = stopping_point(self.vehicle, self.limits)[:2]
        self._takeoff_ned = np.array([xy[0], xy[1], self.limits.ground_down_m - height])
        self.set_mode(FlightMode.TAKEOFF, f"takeoff to {height:.1f} m")
        return RESULT_ACCEPTED

    def request_mode(self, mode: FlightMode) -> int:
        """A mode asked for by a client (OFFBOARD needs a setpoint stream); a MAV_RESULT."""
        if mode is FlightMode.OFFBOARD:
            if not self.setpoint_stream_ok():
                logger.warning("vehicle %d: OFFBOARD denied, no setpoint stream", self.system_id)
                return RESULT_DENIED
            self.set_mode(FlightMode.OFFBOARD, "requested")
            return RESULT_ACCEPTED
        if mode is FlightMode.TAKEOFF:
            return self.takeoff(math.nan)
        self.set_mode(mode, "requested")
        return RESULT_ACCEPTED

    def snapshot(self) -> AutopilotState:
        """The vehicle now, as an `AutopilotState`."""
        v = self.vehicle
        p = v.position_ned_m.copy()
        return AutopilotState(
            time_s=self.now_s,
            position_ned_m=p,
            velocity_ned_mps=v.velocity_ned_mps.copy(),
            yaw_rad=v.yaw_rad,
            position_xy_m=ned_to_scenario_xy(p, self.origin_xy_m),
            altitude_m=self.height_m(),
            mode=self.mode,
            armed=self.armed,
            landed=self.landed,
            gcs_lost=self.gcs_lost,
        )
