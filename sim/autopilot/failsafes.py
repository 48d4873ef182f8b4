"""The simulated vehicle's failsafes, as PX4's commander runs them (pure: no I/O). Each check
takes the vehicle's `FailsafeStatus` and the `FailsafeParams` in force and returns a
`FailsafeDecision` (a mode change, a disarm, a STATUSTEXT for the ground, what to remember), or
None when it has nothing to do; the flight logic applies the decision:

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

`CHECKS` run before each step in PX4's order of precedence (battery last: it may override a
HOLD), each on the status the decisions before it left; `battery_warning` runs when the
battery's warning level rises. Times are simulation time, s. The STATUSTEXTs keep PX4's words
(docs/service.md, "How a vehicle reports a failsafe").
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.battery import BatteryWarning, Thresholds

logger = logging.getLogger(__name__)

LOW_BATTERY_TEXT = "Low battery level, return advised"
"""PX4's STATUSTEXT at BAT_LOW_THR."""

_ACTION_NAMES = {FlightMode.RTL: "Return", FlightMode.LAND: "Land"}

BatteryActionDue = tuple[FlightMode, float]
"""A low-battery action (RTL or LAND) and the simulation time it is due, s."""


@dataclass(frozen=True)
class FailsafeParams:
    """The parameters the failsafes read (values in force; rebuilt on PARAM_SET).

    Attributes:
        offboard_loss_timeout_s: COM_OF_LOSS_T, s.
        offboard_loss_action: COM_OBL_RC_ACT (4 LAND, else HOLD).
        datalink_loss_timeout_s: COM_DL_LOSS_T, s.
        datalink_loss_action: NAV_DLL_ACT (0 none, 1 HOLD, 3 LAND).
        low_battery_action: COM_LOW_BAT_ACT (0 warn, 1 Return, 2 Land, 3 Return then Land).
        battery_action_delay_s: COM_BAT_ACT_T, s.
        disarm_landed_s: COM_DISARM_LAND, s (<= 0: never).
        disarm_preflight_s: COM_DISARM_PRFLT, s (<= 0: never).
        thresholds: BAT_LOW_THR, BAT_CRIT_THR, BAT_EMERGEN_THR.
    """

    offboard_loss_timeout_s: float
    offboard_loss_action: float
    datalink_loss_timeout_s: float
    datalink_loss_action: float
    low_battery_action: float
    battery_action_delay_s: float
    disarm_landed_s: float
    disarm_preflight_s: float
    thresholds: Thresholds

    @classmethod
    def of(cls, param: Callable[[str], float]) -> FailsafeParams:
        """From `param`, the value in force of a parameter by name."""
        return cls(
            offboard_loss_timeout_s=param("COM_OF_LOSS_T"),
            offboard_loss_action=param("COM_OBL_RC_ACT"),
            datalink_loss_timeout_s=param("COM_DL_LOSS_T"),
            datalink_loss_action=param("NAV_DLL_ACT"),
            low_battery_action=param("COM_LOW_BAT_ACT"),
            battery_action_delay_s=param("COM_BAT_ACT_T"),
            disarm_landed_s=param("COM_DISARM_LAND"),
            disarm_preflight_s=param("COM_DISARM_PRFLT"),
            thresholds=Thresholds(
                param("BAT_LOW_THR"), param("BAT_CRIT_THR"), param("BAT_EMERGEN_THR")
            ),
        )


@dataclass(frozen=True)
class FailsafeStatus:
    """What the failsafes read of the vehicle.

    Attributes:
        system_id: MAVLink system id (for the log).
        now_s: Simulation time, s.
        mode: Current flight mode.
        armed: Motors armed.
        landed: On the ground (land detector).
        armed_at_s: Simulation time of the last arming, s.
        landed_at_s: Simulation time of the last touchdown, s (None: not since arming).
        last_setpoint_s: Simulation time of the last offboard setpoint, s.
        last_client_heartbeat_s: Simulation time of the last client HEARTBEAT, s (None: none
            heard yet).
        gcs_lost: The datalink loss was declared (and not yet regained).
        battery_action_due: The low-battery action scheduled, if any.
        battery_warning: The battery's warning level.
        battery_remaining: Charge left, fraction in [0, 1].
    """

    system_id: int
    now_s: float
    mode: FlightMode
    armed: bool
    landed: bool
    armed_at_s: float
    landed_at_s: float | None
    last_setpoint_s: float
    last_client_heartbeat_s: float | None
    gcs_lost: bool
    battery_action_due: BatteryActionDue | None
    battery_warning: BatteryWarning
    battery_remaining: float

    @property
    def airborne(self) -> bool:
        """Armed and in the air."""
        return self.armed and not self.landed


@dataclass(frozen=True)
class FailsafeDecision:
    """What a failsafe asks of the flight logic, applied in this order: remember the datalink
    lost, forget the scheduled battery action, switch mode, disarm, tell the ground, schedule
    a battery action.

    Attributes:
        mode: The mode to switch to (None: keep the mode).
        reason: Why (of the mode change or the disarm, for the log).
        disarm: Disarm (on the ground).
        statustext: (MAV_SEVERITY_*, text) to tell the ground, or None.
        gcs_lost: The datalink is lost from now on.
        drop_battery_action: The scheduled battery action is done with (taken or moot).
        battery_action_due: A battery action to schedule, or None.
    """

    mode: FlightMode | None = None
    reason: str = ""
    disarm: bool = False
    statustext: tuple[int, str] | None = None
    gcs_lost: bool = False
    drop_battery_action: bool = False
    battery_action_due: BatteryActionDue | None = None


Check = Callable[[FailsafeStatus, FailsafeParams], FailsafeDecision | None]
"""One failsafe check: the vehicle's status and the parameters in, a decision or None out."""


def offboard_loss(s: FailsafeStatus, p: FailsafeParams) -> FailsafeDecision | None:
    """OFFBOARD without a setpoint for COM_OF_LOSS_T: COM_OBL_RC_ACT (4 LAND, else HOLD)."""
    if s.mode is not FlightMode.OFFBOARD or not s.armed:
        return None
    if s.now_s - s.last_setpoint_s <= p.offboard_loss_timeout_s:
        return None
    action = FlightMode.LAND if p.offboard_loss_action == 4 else FlightMode.HOLD
    logger.warning("vehicle %d: offboard setpoints lost, %s", s.system_id, action.value)
    return FailsafeDecision(
        mode=action,
        reason="offboard loss",
        statustext=(mavlink2.MAV_SEVERITY_WARNING, f"Offboard lost: {action.value}"),
    )


def datalink_loss(s: FailsafeStatus, p: FailsafeParams) -> FailsafeDecision | None:
    """No client HEARTBEAT for COM_DL_LOSS_T (after one was heard): NAV_DLL_ACT, taken in the
    air unless already landing or already in that mode."""
    last = s.last_client_heartbeat_s
    if last is None or s.gcs_lost:
        return None
    silent_s = s.now_s - last
    if silent_s <= p.datalink_loss_timeout_s:
        return None
    action = {1: FlightMode.HOLD, 3: FlightMode.LAND}.get(int(p.datalink_loss_action))
    logger.warning(
        "vehicle %d: no client heartbeat for %.1f s, action %s",
        s.system_id,
        silent_s,
        action.value if action else "none",
    )
    take = action is not None and s.airborne and s.mode not in (FlightMode.LAND, action)
    return FailsafeDecision(
        mode=action if take else None,
        reason="datalink loss",
        statustext=(mavlink2.MAV_SEVERITY_CRITICAL, "Connection to ground station lost"),
        gcs_lost=True,
    )


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


def battery_warning(
    level: BatteryWarning, s: FailsafeStatus, p: FailsafeParams
) -> FailsafeDecision:
    """The battery's warning rose to `level`: tell the ground, and schedule the action
    COM_BAT_ACT_T from now (in the air, unless already landing or returning for a return)."""
    logger.warning(
        "vehicle %d: battery %s (%.1f %% left)", s.system_id, level.name, 100 * s.battery_remaining
    )
    if level is BatteryWarning.LOW:
        return FailsafeDecision(statustext=(mavlink2.MAV_SEVERITY_WARNING, LOW_BATTERY_TEXT))
    critical = level is BatteryWarning.CRITICAL
    severity = mavlink2.MAV_SEVERITY_CRITICAL if critical else mavlink2.MAV_SEVERITY_EMERGENCY
    words = "Critical battery level" if critical else "Dangerous battery level"
    action = battery_action(level, int(p.low_battery_action))
    if action is None or not s.airborne or _already(s.mode, action):
        return FailsafeDecision(
            statustext=(severity, f"{words}, {'return now' if critical else 'land now'}")
        )
    delay_s = max(0.0, p.battery_action_delay_s)
    return FailsafeDecision(
        statustext=(
            severity,
            f"{words}, executing {_ACTION_NAMES[action]} in {delay_s:.0f} seconds",
        ),
        battery_action_due=(action, s.now_s + delay_s),
    )


def scheduled_battery_action(s: FailsafeStatus, p: FailsafeParams) -> FailsafeDecision | None:
    """Once the scheduled battery action is due: take it (in the air, unless already landing or
    returning for a return) and forget it."""
    due = s.battery_action_due
    if due is None or s.now_s < due[1]:
        return None
    action = due[0]
    take = s.airborne and not _already(s.mode, action)
    return FailsafeDecision(
        mode=action if take else None,
        reason=f"battery {s.battery_warning.name.lower()}",
        drop_battery_action=True,
    )


def auto_disarm(s: FailsafeStatus, p: FailsafeParams) -> FailsafeDecision | None:
    """COM_DISARM_LAND after touchdown, COM_DISARM_PRFLT after arming without taking off."""
    if not (s.armed and s.landed):
        return None
    if s.landed_at_s is not None:
        delay = p.disarm_landed_s
        if delay > 0 and s.now_s - s.landed_at_s >= delay:
            return FailsafeDecision(disarm=True, reason="landed")
    else:
        delay = p.disarm_preflight_s
        if delay > 0 and s.now_s - s.armed_at_s >= delay:
            return FailsafeDecision(disarm=True, reason="no takeoff after arming")
    return None


CHECKS: tuple[Check, ...] = (offboard_loss, datalink_loss, scheduled_battery_action, auto_disarm)
"""The checks before each step, in PX4's order of precedence."""
