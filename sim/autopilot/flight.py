"""The flight logic of a PX4-like multirotor around the kinematic core (pure: no I/O).

Modes HOLD (AUTO.LOITER; DO_REPOSITION flies it to a point), TAKEOFF (AUTO.TAKEOFF), LAND
(AUTO.LAND), RTL (AUTO.RTL, `rtl`), MISSION (AUTO.MISSION, `mission_flight`) and OFFBOARD;
`armed` and `landed` complete the state (landed/disarmed, armed on the ground, in the air). A
vehicle disarmed in the air (force disarm) falls under gravity to the ground. The failsafes
(`failsafes`: offboard loss, datalink loss, low battery, auto-disarm) are checked before each
step, the battery (`battery`) draws energy at each step. The failsafes, RTL and MISSION are
values in, a decision out: this class hands them what they read of the vehicle and applies
what they decide (a mode change, a disarm, a STATUSTEXT, guidance).

Everything runs on simulation time: `step(now_s, dt_s)` integrates the vehicle (`sim.vehicle`),
checks the timeouts against `now_s` and runs the land detector. Frames: local NED (north, east,
down, m) around the scenario-plane point `local_origin_xy_m` (`isac_mission.frames`).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from isac_mission.frames import GeoPoint, geodetic_to_scenario, ned_to_scenario_xy, scenario_to_ned
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from isac_mission.types import FloatArray
from sim.autopilot import failsafes
from sim.autopilot.battery import Battery
from sim.autopilot.failsafes import (
    BatteryActionDue,
    FailsafeDecision,
    FailsafeParams,
    FailsafeStatus,
)
from sim.autopilot.guidance import Guidance, fall_step, goto, land_below
from sim.autopilot.mission_flight import MissionFrame, MissionRunner, MissionVehicle
from sim.autopilot.params import LIMIT_FIELDS, Param
from sim.autopilot.rtl import Rtl, RtlPhase
from sim.autopilot.settings import AutopilotSettings
from sim.autopilot.state import AutopilotState
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
        self.say = say
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
        self.armed_at_s = 0.0
        self.landed_at_s: float | None = None
        self._hold_ned = self.vehicle.position_ned_m.copy()
        self._hold_speed_mps: float | None = None
        self._hold_yaw_rad = math.nan
        self._land_xy_ned = self.vehicle.position_ned_m[:2].copy()
        self._takeoff_ned = self.vehicle.position_ned_m.copy()
        self.rtl: Rtl | None = None
        """The return in progress (mode RTL)."""
        self.home_ned = self.vehicle.position_ned_m.copy()
        """Where the vehicle armed last (local NED (3,), m)."""
        self.battery = Battery(settings.battery)
        self.battery_action_due: BatteryActionDue | None = None
        """A low-battery action and the simulation time it is due (COM_BAT_ACT_T)."""
        self.failsafe_params = FailsafeParams.of(self.param)
        """The failsafes' parameters in force (refreshed on PARAM_SET)."""
        self.mission = MissionRunner(
            MissionFrame(settings.geo_origin, self.origin_xy_m, self.limits.ground_down_m),
            self.system_id,
        )
        """The uploaded plan and its progress (flown in MISSION)."""
        self.offboard_sp: Guidance | None = None
        self.last_setpoint_s = -math.inf
        self.last_client_heartbeat_s: float | None = None
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
        self.failsafe_params = FailsafeParams.of(self.param)

    def step(self, now_s: float, dt_s: float) -> None:
        """Advance to simulation time `now_s` (s) by `dt_s` (s): failsafes, physics, battery,
        land detector, then a new snapshot."""
        self.now_s = now_s
        self._check_failsafes()
        v0 = self.vehicle
        if not self.armed:
            if self.height_m() > 0.0:
                self.vehicle = fall_step(v0, self.limits.ground_down_m, dt_s)
        else:
            guidance = self._guidance()
            if guidance is not None:
                self.vehicle = vehicle_step(
                    v0, guidance.setpoint, guidance.limits(self.limits), dt_s
                )
        v1 = self.vehicle
        self.accel_ned_mps2 = (v1.velocity_ned_mps - v0.velocity_ned_mps) / dt_s
        self.yaw_rate_rps = wrap_pi(v1.yaw_rad - v0.yaw_rad) / dt_s
        vn, ve, vd = v1.velocity_ned_mps.tolist()
        level = self.battery.step(
            dt_s, self.armed, math.hypot(vn, ve), -vd, self.failsafe_params.thresholds
        )
        if level is not None:
            status = self._failsafe_status()
            self._apply(failsafes.battery_warning(level, status, self.failsafe_params))
        self._update_land_detector()
        self.state = self.snapshot()

    def _failsafe_status(self) -> FailsafeStatus:
        """What the failsafes read of the vehicle now."""
        return FailsafeStatus(
            system_id=self.system_id,
            now_s=self.now_s,
            mode=self.mode,
            armed=self.armed,
            landed=self.landed,
            armed_at_s=self.armed_at_s,
            landed_at_s=self.landed_at_s,
            last_setpoint_s=self.last_setpoint_s,
            last_client_heartbeat_s=self.last_client_heartbeat_s,
            gcs_lost=self.gcs_lost,
            battery_action_due=self.battery_action_due,
            battery_warning=self.battery.warning,
            battery_remaining=self.battery.remaining,
        )

    def _check_failsafes(self) -> None:
        """Every failsafe check in order, each on the status the decisions before it left."""
        status = self._failsafe_status()
        for check in failsafes.CHECKS:
            decision = check(status, self.failsafe_params)
            if decision is not None:
                self._apply(decision)
                status = self._failsafe_status()

    def _apply(self, d: FailsafeDecision) -> None:
        """Carry out a failsafe's decision (in `FailsafeDecision`'s order)."""
        if d.gcs_lost:
            self.gcs_lost = True
        if d.drop_battery_action:
            self.battery_action_due = None
        if d.mode is not None:
            self.set_mode(d.mode, d.reason)
        if d.disarm:
            self.disarm(d.reason)
        if d.statustext is not None:
            self.say(*d.statustext)
        if d.battery_action_due is not None:
            self.battery_action_due = d.battery_action_due
        if d.gcs_lost:
            self.state = self.snapshot()

    def height_m(self) -> float:
        """Height above the ground, m."""
        return float(self.limits.ground_down_m - self.vehicle.position_ned_m[2])

    def cruise_mps(self) -> float:
        """MPC_XY_CRUISE, the horizontal speed of the autonomous modes, m/s."""
        return self.param("MPC_XY_CRUISE")

    def land_here(self, xy_ned_m: FloatArray) -> Guidance:
        """Land over `xy_ned_m` (2,) (LAND's descent profile)."""
        return land_below(
            xy_ned_m,
            self.height_m(),
            self.limits,
            self.settings.land_slow_below_m,
            self.param("MPC_LAND_SPEED"),
        )

    def _guidance(self) -> Guidance | None:
        """What the armed vehicle tracks this step; None = motors idle (stay put)."""
        mode = self.mode
        if mode is FlightMode.MISSION:
            return self._mission_guidance()
        if self.landed and mode in (FlightMode.HOLD, FlightMode.LAND, FlightMode.RTL):
            return None
        if mode is FlightMode.TAKEOFF:
            return goto(self._takeoff_ned, None)
        if mode is FlightMode.HOLD:
            return goto(self._hold_ned, self._hold_speed_mps, self._hold_yaw_rad)
        if mode is FlightMode.LAND:
            return self.land_here(self._land_xy_ned)
        if mode is FlightMode.RTL and self.rtl is not None:
            guidance = self.rtl.guidance(self.vehicle, self.now_s)
            return guidance if guidance is not None else self.land_here(self.rtl.home_ned_m[:2])
        return self.offboard_sp

    def _mission_guidance(self) -> Guidance | None:
        """MISSION's guidance this step: the mission's decision, applied."""
        decision = self.mission.fly(
            MissionVehicle(
                now_s=self.now_s,
                position_ned_m=self.vehicle.position_ned_m,
                landed=self.landed,
                home_ned_m=self.home_ned,
                cruise_mps=self.cruise_mps(),
                acceptance_radius_m=self.param("NAV_ACC_RAD"),
                altitude_radius_m=self.param("NAV_MC_ALT_RAD"),
            )
        )
        if decision.mode is not None:
            self.set_mode(decision.mode, decision.reason)
            return None
        if decision.land_xy_ned_m is not None:
            return self.land_here(decision.land_xy_ned_m)
        return decision.guidance

    def set_mode(self, mode: FlightMode, reason: str) -> None:
        """Switch to `mode` (HOLD holds at the stopping point, LAND lands below it, RTL returns
        from it, MISSION resumes the plan at its current item)."""
        stop = stopping_point(self.vehicle, self.limits)
        if mode is FlightMode.HOLD:
            self._hold_ned, self._hold_speed_mps, self._hold_yaw_rad = stop, None, math.nan
        elif mode is FlightMode.LAND:
            self._land_xy_ned = stop[:2]
        elif mode is FlightMode.RTL:
            self.rtl = Rtl.start(
                stop,
                self.home_ned,
                self.param("RTL_RETURN_ALT"),
                self.param("RTL_DESCEND_ALT"),
                self.param("RTL_LAND_DELAY"),
                self.cruise_mps(),
            )
        elif mode is FlightMode.MISSION:
            self.mission.resume(stop)
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

    def landing(self) -> bool:
        """True while the vehicle descends to land (LAND, RTL's last leg, a mission's LAND)."""
        if self.landed:
            return False
        if self.mode is FlightMode.LAND:
            return True
        if self.mode is FlightMode.RTL:
            return self.rtl is not None and self.rtl.phase is RtlPhase.LAND
        return self.mode is FlightMode.MISSION and self.mission.landing

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
        self.offboard_sp = Guidance(setpoint)
        self.last_setpoint_s = self.now_s

    def client_heartbeat(self, link_name: str) -> None:
        """A client HEARTBEAT was heard on link `link_name` (restores a lost GCS)."""
        if self.gcs_lost:
            logger.info(
                "vehicle %d: client heartbeat regained on %s link", self.system_id, link_name
            )
            self.gcs_lost = False
            self.state = self.snapshot()
        self.last_client_heartbeat_s = self.now_s

    def _update_land_detector(self) -> None:
        height = self.height_m()
        v_down = float(self.vehicle.velocity_ned_mps[2])
        if self.landed and self.armed and height > _AIRBORNE_ALT_M:
            self.landed = False
            self.landed_at_s = None
            logger.info("vehicle %d: airborne", self.system_id)
        elif not self.landed and height < _LANDED_ALT_M and abs(v_down) <= 0.05:
            self.landed = True
            self.landed_at_s = self.now_s
            logger.info("vehicle %d: landed", self.system_id)
            if self.mode is FlightMode.MISSION:
                self.mission.touched_down(self.vehicle.position_ned_m)
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
        self.armed_at_s = self.now_s
        self.landed_at_s = None
        self.home_ned = self.vehicle.position_ned_m.copy()
        if self.mode in (FlightMode.LAND, FlightMode.TAKEOFF, FlightMode.RTL):
            self.set_mode(FlightMode.HOLD, "armed")
        logger.info("vehicle %d: armed", self.system_id)
        self.state = self.snapshot()
        return RESULT_ACCEPTED

    def disarm(self, reason: str, force: bool = False) -> int:
        """Disarm; a MAV_RESULT. In the air only with `force` (PX4's 21196): the motors stop
        and the vehicle falls."""
        if not self.armed:
            return RESULT_ACCEPTED
        if not self.landed and not force:
            return RESULT_DENIED
        self.armed = False
        self.battery_action_due = None
        if self.landed:
            self.vehicle = replace(self.vehicle, velocity_ned_mps=np.zeros(3))
            logger.info("vehicle %d: disarmed (%s)", self.system_id, reason)
        else:
            logger.warning(
                "vehicle %d: disarmed in the air at %.1f m (%s): falling",
                self.system_id,
                self.height_m(),
                reason,
            )
        self.state = self.snapshot()
        return RESULT_ACCEPTED

    def takeoff(self, alt_amsl_m: float) -> int:
        """Take off to `alt_amsl_m` (NaN: MIS_TAKEOFF_ALT above home), clamped to the altitude
        band; a MAV_RESULT."""
        if not self.armed:
            return RESULT_DENIED
        height = (
            alt_amsl_m - self.home_amsl_m()
            if math.isfinite(alt_amsl_m)
            else self.param("MIS_TAKEOFF_ALT")
        )
        height = min(max(height, self.settings.min_altitude_m), self.settings.max_altitude_m)
        xy = stopping_point(self.vehicle, self.limits)[:2]
        self._takeoff_ned = np.array([xy[0], xy[1], self.limits.ground_down_m - height])
        self.set_mode(FlightMode.TAKEOFF, f"takeoff to {height:.1f} m")
        return RESULT_ACCEPTED

    def reposition(self, target_ned_m: FloatArray, speed_mps: float, yaw_rad: float) -> int:
        """MAV_CMD_DO_REPOSITION: HOLD, flying to `target_ned_m` (3,) at `speed_mps` (<= 0:
        MPC_XY_CRUISE) and holding there with heading `yaw_rad` (NaN: keep); a MAV_RESULT."""
        if not self.armed or self.landed:
            return RESULT_DENIED
        self.set_mode(FlightMode.HOLD, "reposition")
        self._hold_ned = np.array(target_ned_m, dtype=float)
        self._hold_speed_mps = speed_mps if speed_mps > 0 else self.cruise_mps()
        self._hold_yaw_rad = yaw_rad
        return RESULT_ACCEPTED

    def request_mode(self, mode: FlightMode) -> int:
        """A mode asked for by a client (OFFBOARD needs a setpoint stream, RTL a vehicle in
        the air, MISSION a plan); a MAV_RESULT."""
        if mode is FlightMode.OFFBOARD:
            if not self.setpoint_stream_ok():
                logger.warning("vehicle %d: OFFBOARD denied, no setpoint stream", self.system_id)
                return RESULT_DENIED
        elif mode is FlightMode.TAKEOFF:
            return self.takeoff(math.nan)
        elif mode is FlightMode.RTL and (not self.armed or self.landed):
            return RESULT_DENIED
        elif mode is FlightMode.MISSION and not self.mission.items:
            logger.warning("vehicle %d: MISSION denied, no mission", self.system_id)
            return RESULT_DENIED
        self.set_mode(mode, "requested")
        return RESULT_ACCEPTED

    def home_amsl_m(self) -> float:
        """Altitude of home above mean sea level, m."""
        return self.settings.geo_origin.alt_amsl_m + float(
            self.limits.ground_down_m - self.home_ned[2]
        )

    def geodetic_to_ned(self, lat_deg: float, lon_deg: float, alt_amsl_m: float) -> FloatArray:
        """The local NED position (3,), m, of a geodetic point (altitude AMSL)."""
        xy, alt_m = geodetic_to_scenario(
            GeoPoint(lat_deg, lon_deg, alt_amsl_m), self.settings.geo_origin
        )
        return scenario_to_ned(xy, alt_m - self.limits.ground_down_m, self.origin_xy_m)

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
            battery_remaining=self.battery.remaining,
        )
