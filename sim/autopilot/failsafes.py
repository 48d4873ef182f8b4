"""The simulated vehicle's failsafes, as PX4's commander runs them (pure: no I/O; each function
takes the `FlightLogic` and may change its mode, telling the ground with a STATUSTEXT):

- offboard loss: in OFFBOARD, no setpoint for COM_OF_LOSS_T -> COM_OBL_RC_ACT (HOLD or LAND);
- datalink loss: after a client HEARTBEAT was heard, silence for COM_DL_LOSS_T makes an airborne
  vehicle take NAV_DLL_ACT (none, HOLD or LAND);
- low battery (PX4 v1.13's commander, `warn_user_about_battery` / `get_battery_failsafe_action`):
  at BAT_LOW_THR a warning; at BAT_CRIT_THR and BAT_EMERGEN_THR the COM_LOW_BAT_ACT action
  (0 warning only, 1 Return, 2 Land, 3 Return at critical and Land at emergency), announced at
  once and taken COM_BAT_ACT_T seconds later, unless the vehicle is already landing (or, for a
  return, already returning);
- auto-disarm: COM_DISARM_LAND after touching down, COM_DISARM_PRFLT after arming without
  taking off.

The STATUSTEXTs keep PX4's words (docs/service.md, "How a vehicle reports a failsafe").
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.battery import BatteryWarning, Thresholds

if TYPE_CHECKING:
    from sim.autopilot.flight import FlightLogic

logger = logging.getLogger(__name__)

LOW_BATTERY_TEXT = "Low battery level, return advised"
"""PX4's STATUSTEXT at BAT_LOW_THR."""

_ACTION_NAMES = {FlightMode.RTL: "Return", FlightMode.LAND: "Land"}


def check_failsafes(f: FlightLogic) -> None:
    """Every failsafe, in PX4's order of precedence (battery last: it may override a HOLD)."""
    check_offboard_loss(f)
    check_datalink_loss(f)
    check_battery_action(f)
    check_auto_disarm(f)


def check_offboard_loss(f: FlightLogic) -> None:
    """OFFBOARD without a setpoint for COM_OF_LOSS_T: COM_OBL_RC_ACT (4 LAND, else HOLD)."""
    if f.mode is not FlightMode.OFFBOARD or not f.armed:
        return
    if f.now_s - f.last_setpoint_s <= f.param("COM_OF_LOSS_T"):
        return
    action = FlightMode.LAND if f.param("COM_OBL_RC_ACT") == 4 else FlightMode.HOLD
    logger.warning("vehicle %d: offboard setpoints lost, %s", f.system_id, action.value)
    f.set_mode(action, "offboard loss")
    f.say(mavlink2.MAV_SEVERITY_WARNING, f"Offboard lost: {action.value}")


def check_datalink_loss(f: FlightLogic) -> None:
    """No client HEARTBEAT for COM_DL_LOSS_T (after one was heard): NAV_DLL_ACT."""
    last = f.last_client_heartbeat_s
    if last is None or f.gcs_lost:
        return
    silent_s = f.now_s - last
    if silent_s <= f.param("COM_DL_LOSS_T"):
        return
    f.gcs_lost = True
    action = {1: FlightMode.HOLD, 3: FlightMode.LAND}.get(int(f.param("NAV_DLL_ACT")))
    logger.warning(
        "vehicle %d: no client heartbeat for %.1f s, action %s",
        f.system_id,
        silent_s,
        action.value if action else "none",
    )
    airborne = f.armed and not f.landed
    if action is not None and airborne and f.mode not in (FlightMode.LAND, action):
        f.set_mode(action, "datalink loss")
    f.say(mavlink2.MAV_SEVERITY_CRITICAL, "Connection to ground station lost")
    f.state = f.snapshot()


def battery_thresholds(f: FlightLogic) -> Thresholds:
    """BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR in force."""
    return Thresholds(f.param("BAT_LOW_THR"), f.param("BAT_CRIT_THR"), f.param("BAT_EMERGEN_THR"))


def battery_action(level: BatteryWarning, low_bat_act: int) -> FlightMode | None:
    """COM_LOW_BAT_ACT's mode for warning `level` (None: a warning only)."""
    if level is BatteryWarning.CRITICAL:
        return {1: FlightMode.RTL, 2: FlightMode.LAND, 3: FlightMode.RTL}.get(low_bat_act)
    if level is BatteryWarning.EMERGENCY:
        return {1: FlightMode.RTL, 2: FlightMode.LAND, 3: FlightMode.LAND}.get(low_bat_act)
    return None


def _already(mode: FlightMode, action: FlightMode) -> bool:
    """PX4 takes no battery action when already landing, or already returning for a return."""
    return mode is FlightMode.LAND or (action is FlightMode.RTL and mode is FlightMode.RTL)


def on_battery_warning(f: FlightLogic, level: BatteryWarning) -> None:
    """The battery's warning rose to `level`: tell the ground, and schedule the action."""
    logger.warning(
        "vehicle %d: battery %s (%.1f %% left)", f.system_id, level.name, 100 * f.battery.remaining
    )
    if level is BatteryWarning.LOW:
        f.say(mavlink2.MAV_SEVERITY_WARNING, LOW_BATTERY_TEXT)
        return
    critical = level is BatteryWarning.CRITICAL
    severity = mavlink2.MAV_SEVERITY_CRITICAL if critical else mavlink2.MAV_SEVERITY_EMERGENCY
    words = "Critical battery level" if critical else "Dangerous battery level"
    action = battery_action(level, int(f.param("COM_LOW_BAT_ACT")))
    airborne = f.armed and not f.landed
    if action is None or not airborne or _already(f.mode, action):
        f.say(severity, f"{words}, {'return now' if critical else 'land now'}")
        return
    delay_s = max(0.0, f.param("COM_BAT_ACT_T"))
    f.say(severity, f"{words}, executing {_ACTION_NAMES[action]} in {delay_s:.0f} seconds")
    f.battery_action_due = (action, f.now_s + delay_s)


def check_battery_action(f: FlightLogic) -> None:
    """Take a scheduled battery action once its COM_BAT_ACT_T delay is over."""
    due = f.battery_action_due
    if due is None or f.now_s < due[1]:
        return
    f.battery_action_due = None
    action = due[0]
    if f.armed and not f.landed and not _already(f.mode, action):
        f.set_mode(action, f"battery {f.battery.warning.name.lower()}")


def check_auto_disarm(f: FlightLogic) -> None:
    """COM_DISARM_LAND after touchdown, COM_DISARM_PRFLT after arming without taking off."""
    if not (f.armed and f.landed):
        return
    now = f.now_s
    if f.landed_at_s is not None:
        delay = f.param("COM_DISARM_LAND")
        if delay > 0 and now - f.landed_at_s >= delay:
            f.disarm("landed")
    else:
        delay = f.param("COM_DISARM_PRFLT")
        if delay > 0 and now - f.armed_at_s >= delay:
            f.disarm("no takeoff after arming")
