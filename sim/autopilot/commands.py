"""What the simulated vehicle obeys: commands, mode changes, setpoints and pings.

COMMAND_LONG and COMMAND_INT (arm/disarm, with param2 = 21196 a force disarm in the air;
takeoff, land, NAV_RETURN_TO_LAUNCH, DO_REPOSITION, MISSION_START, DO_SET_MISSION_CURRENT,
DO_SET_MODE, SET_MESSAGE_INTERVAL, REQUEST_MESSAGE, REQUEST_AUTOPILOT_CAPABILITIES,
GET_HOME_POSITION; anything else UNSUPPORTED),
SET_MODE, SET_POSITION_TARGET_LOCAL_NED (MAV_FRAME_LOCAL_NED only; position and/or velocity, yaw
and yaw rate by type_mask) and PING. Every command is answered with a COMMAND_ACK. Bad input is
counted (`reject`): a NaN, infinite or absurd integer parameter (DENIED, as PX4 does), an
unsupported frame or type mask, a non-finite setpoint (dropped), a setpoint outside the area or
the altitude band (clamped). PX4 modes are decoded by `isac_mission.mavwire.modes`.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import numpy as np

from isac_mission.frames import ned_to_scenario_xy, scenario_to_ned
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode, mode_from_px4, px4_main_sub
from isac_mission.mavwire.ports import Address
from isac_mission.types import FloatArray
from sim.autopilot.flight import RESULT_ACCEPTED, RESULT_DENIED, RESULT_UNSUPPORTED, FlightLogic
from sim.autopilot.link import VehicleLink
from sim.autopilot.params import Reject
from sim.autopilot.telemetry import Telemetry, default_intervals
from sim.vehicle import Setpoint

logger = logging.getLogger(__name__)

INTEGER_PARAMS: dict[int, int] = {
    mavlink2.MAV_CMD_DO_SET_MODE: 3,
    mavlink2.MAV_CMD_MISSION_START: 2,
    mavlink2.MAV_CMD_DO_SET_MISSION_CURRENT: 1,
    mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL: 1,
    mavlink2.MAV_CMD_REQUEST_MESSAGE: 1,
}
"""Commands whose first n parameters are integers carried in floats (a mode, a message id)."""
FORCE_DISARM_MAGIC = 21196
"""MAV_CMD_COMPONENT_ARM_DISARM param2 that disarms in the air (PX4's kill)."""
REPOSITION_CHANGE_MODE = int(mavlink2.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE)
RELATIVE_ALT_FRAMES = (
    mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
)


class CommandHandler:
    """The command side of one vehicle (handlers take (link, message, sender))."""

    def __init__(self, flight: FlightLogic, telemetry: Telemetry, reject: Reject) -> None:
        self._flight = flight
        self._telemetry = telemetry
        self._reject = reject
        self._sysid = flight.system_id

    def on_ping(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """PING addressed to everyone: answered to its sender."""
        if msg.target_system != 0:
            return  # a reply to a ping of ours (we send none)
        link.send(
            mavlink2.MAVLink_ping_message(
                msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent()
            ),
            addr,
        )

    def _ack(self, link: VehicleLink, msg: Any, addr: Address, command: int, result: int) -> None:
        link.send(
            mavlink2.MAVLink_command_ack_message(
                command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            ),
            addr,
        )

    def on_command_long(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """COMMAND_LONG: param1 .. param7."""
        params = (
            msg.param1,
            msg.param2,
            msg.param3,
            msg.param4,
            msg.param5,
            msg.param6,
            msg.param7,
        )
        self._on_command(link, msg, addr, int(msg.command), tuple(float(p) for p in params), None)

    def on_command_int(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """COMMAND_INT: param1 .. param4, x, y, z."""
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z)
        p = tuple(float(x) for x in params)
        self._on_command(link, msg, addr, int(msg.command), p, int(msg.frame))

    def _on_command(
        self,
        link: VehicleLink,
        msg: Any,
        addr: Address,
        command: int,
        p: tuple[float, ...],
        frame: int | None,
    ) -> None:
        """One command; `frame` is COMMAND_INT's (x, y in degE7), None for COMMAND_LONG."""
        flight = self._flight
        builders = self._telemetry.builders
        followup: Any = None
        n_ints = INTEGER_PARAMS.get(command, 0)
        if not all(math.isfinite(x) and abs(x) < 2**31 for x in p[:n_ints]):
            # NaN, inf or absurd where an integer is expected: refused, as PX4 does.
            self._reject("bad_command_param", f"command {command} {p[:n_ints]} from {addr}")
            self._ack(link, msg, addr, command, RESULT_DENIED)
            return
        mission = flight.mission
        if command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
            force = p[1] == FORCE_DISARM_MAGIC
            if p[0] >= 0.5:
                result = flight.arm()
            else:
                result = flight.disarm("forced" if force else "commanded", force=force)
        elif command == mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            result = flight.request_mode(FlightMode.RTL)
        elif command == mavlink2.MAV_CMD_DO_REPOSITION:
            result = self._reposition(p, frame)
        elif command == mavlink2.MAV_CMD_MISSION_START:
            first = int(p[0])
            if mission.items and 0 < first < len(mission.items):
                mission.set_current(first)
            result = flight.request_mode(FlightMode.MISSION)
        elif command == mavlink2.MAV_CMD_DO_SET_MISSION_CURRENT:
            ok = 0 <= int(p[0]) < len(mission.items)
            if ok:
                mission.set_current(int(p[0]))
            result = RESULT_ACCEPTED if ok else RESULT_DENIED
        elif command == mavlink2.MAV_CMD_NAV_TAKEOFF:
            result = flight.takeoff(p[6])
        elif command == mavlink2.MAV_CMD_NAV_LAND:
            result = flight.request_mode(FlightMode.LAND)
        elif command == mavlink2.MAV_CMD_DO_SET_MODE:
            result = self._command_set_mode(int(p[0]), int(p[1]), int(p[2]))
        elif command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_message_interval(link, int(p[0]), p[1])
        elif command == mavlink2.MAV_CMD_REQUEST_MESSAGE:
            builder = builders.get(int(p[0]))
            result = RESULT_ACCEPTED if builder else RESULT_UNSUPPORTED
            followup = builder() if builder else None
        elif command == mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            result = RESULT_ACCEPTED
            followup = self._telemetry.autopilot_version()
        elif command == mavlink2.MAV_CMD_GET_HOME_POSITION:
            result = RESULT_ACCEPTED
            followup = self._telemetry.home_position()
        else:
            result = RESULT_UNSUPPORTED
        level = logging.INFO if result == RESULT_ACCEPTED else logging.WARNING
        logger.log(level, "vehicle %d: command %d %s -> result %d", self._sysid, command, p, result)
        self._ack(link, msg, addr, command, result)
        if followup is not None:
            link.send(followup, addr)

    def _reposition(self, p: tuple[float, ...], frame: int | None) -> int:
        """DO_REPOSITION: param1 speed (m/s, -1 default), param2 flags (CHANGE_MODE: switch to
        HOLD; without it only a vehicle already in HOLD moves, as PX4's navigator does), param4
        yaw (rad, NaN keep), lat, lon (degrees; degE7 in COMMAND_INT; NaN here) and altitude
        (AMSL, above home in the relative frames; NaN: the present one)."""
        flight = self._flight
        here = flight.vehicle.position_ned_m
        scale = 1e-7 if frame is not None else 1.0
        lat, lon, alt = p[4] * scale, p[5] * scale, p[6]
        if frame in RELATIVE_ALT_FRAMES:
            alt += flight.home_amsl_m()
        if not (math.isfinite(lat) and math.isfinite(lon)) or (lat == 0.0 and lon == 0.0):
            target = here.copy()
        else:
            if not (abs(lat) <= 90.0 and abs(lon) <= 180.0):
                return RESULT_DENIED
            target = flight.geodetic_to_ned(lat, lon, flight.home_amsl_m())
        target[2] = flight.geodetic_to_ned(0.0, 0.0, alt)[2] if math.isfinite(alt) else here[2]
        pos = target.copy()
        self._clamp_position_setpoint(pos, ("reposition", 0))
        speed = p[0] if math.isfinite(p[0]) else -1.0
        change_mode = math.isfinite(p[1]) and int(p[1]) & REPOSITION_CHANGE_MODE
        if not change_mode and flight.mode is not FlightMode.HOLD:
            # PX4: accepted, but the navigator repositions only in HOLD (or on a mode switch).
            return RESULT_ACCEPTED if flight.armed and not flight.landed else RESULT_DENIED
        return flight.reposition(pos, speed, p[3])

    def _command_set_mode(self, base_mode: int, main_mode: int, sub_mode: int) -> int:
        if not base_mode & mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return RESULT_UNSUPPORTED
        mode = mode_from_px4(main_mode, sub_mode)
        if mode is None:
            return RESULT_UNSUPPORTED
        return self._flight.request_mode(mode)

    def on_set_mode(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """SET_MODE (the PX4 custom mode in custom_mode), answered as DO_SET_MODE."""
        main, sub = px4_main_sub(int(msg.custom_mode))
        result = self._command_set_mode(int(msg.base_mode), main, sub)
        self._ack(link, msg, addr, mavlink2.MAV_CMD_DO_SET_MODE, result)

    def _set_message_interval(self, link: VehicleLink, msg_id: int, interval_us: float) -> int:
        if msg_id not in self._telemetry.builders or not math.isfinite(interval_us):
            return RESULT_UNSUPPORTED
        if interval_us < 0:
            link.intervals_s.pop(msg_id, None)
        elif interval_us == 0:
            default = default_intervals(self._flight.settings).get(msg_id)
            if default is None:
                link.intervals_s.pop(msg_id, None)
            else:
                link.intervals_s[msg_id] = default
        else:
            link.intervals_s[msg_id] = interval_us * 1e-6
        link.next_due_s[msg_id] = self._flight.now_s
        return RESULT_ACCEPTED

    def on_position_target(self, link: VehicleLink, msg: Any, addr: Address) -> None:
        """SET_POSITION_TARGET_LOCAL_NED: the offboard setpoint (checked, clamped)."""
        if msg.coordinate_frame != mavlink2.MAV_FRAME_LOCAL_NED:
            self._reject("unsupported_frame", f"frame {msg.coordinate_frame} from {addr}")
            return
        mask = int(msg.type_mask)
        raw_p = (float(msg.x), float(msg.y), float(msg.z))
        raw_v = (float(msg.vx), float(msg.vy), float(msg.vz))
        use_p = [not mask & bit for bit in (1, 2, 4)]
        use_v = [not mask & bit for bit in (8, 16, 32)]
        if not any(use_p) and not any(use_v):
            self._reject("unsupported_type_mask", f"type_mask 0x{mask:03X} from {addr}")
            return
        used = [x for x, u in zip(raw_p + raw_v, use_p + use_v, strict=True) if u]
        if not all(math.isfinite(x) for x in used):
            self._reject("non_finite_setpoint", f"{raw_p} {raw_v} mask 0x{mask:03X} from {addr}")
            return
        pos = np.array([x if u else math.nan for x, u in zip(raw_p, use_p, strict=True)])
        vel = np.array([x if u else math.nan for x, u in zip(raw_v, use_v, strict=True)])
        self._clamp_position_setpoint(pos, addr)
        yaw = (
            float(msg.yaw) if not mask & mavlink2.POSITION_TARGET_TYPEMASK_YAW_IGNORE else math.nan
        )
        yaw_rate = (
            float(msg.yaw_rate)
            if not mask & mavlink2.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
            else math.nan
        )
        self._flight.set_offboard_setpoint(
            Setpoint(
                position_ned_m=pos,
                velocity_ned_mps=vel,
                yaw_rad=yaw if math.isfinite(yaw) else math.nan,
                yaw_rate_rps=yaw_rate if math.isfinite(yaw_rate) else math.nan,
            )
        )

    def _clamp_position_setpoint(self, pos: FloatArray, addr: Address) -> None:
        """Clamp a local NED position setpoint (3,) in place to the area and altitude band."""
        s = self._flight.settings
        origin = self._flight.origin_xy_m
        xy = ned_to_scenario_xy(pos, origin)
        for axis_ned, axis_xy in ((0, 1), (1, 0)):
            scn = xy[axis_xy]
            if math.isnan(scn):
                continue
            lo, hi = s.area_min_xy_m[axis_xy], s.area_max_xy_m[axis_xy]
            if not lo <= scn <= hi:
                self._reject(
                    "out_of_area", f"{'xy'[axis_xy]} = {scn:.1f} m outside [{lo}, {hi}] from {addr}"
                )
                xy[axis_xy] = min(max(scn, lo), hi)
                pos[axis_ned] = scenario_to_ned(xy, 0.0, origin)[axis_ned]
        if not math.isnan(pos[2]):
            ground = self._flight.limits.ground_down_m
            alt = ground - pos[2]
            if alt < s.min_altitude_m:
                reason = "below_ground" if alt < 0.0 else "below_min_altitude"
                self._reject(reason, f"altitude {alt:.1f} m < {s.min_altitude_m} m from {addr}")
                pos[2] = ground - s.min_altitude_m
            elif alt > s.max_altitude_m:
                self._reject(
                    "above_max_altitude", f"altitude {alt:.1f} m > {s.max_altitude_m} m from {addr}"
                )
                pos[2] = ground - s.max_altitude_m
