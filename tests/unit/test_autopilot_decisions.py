"""The simulated vehicle's failsafes and mission flight as decisions, without a vehicle: each
failsafe's trigger and what it asks (mode, STATUSTEXT, disarm, what to remember) from a
hand-built `FailsafeStatus`, and the mission's next-item decisions from a hand-built
`MissionVehicle` (frames: local NED, m; times: simulation time, s)."""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from isac_mission.frames import PX4_SITL_ORIGIN, scenario_to_geodetic
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot import failsafes
from sim.autopilot.battery import BatteryWarning, Thresholds
from sim.autopilot.failsafes import (
    LOW_BATTERY_TEXT,
    FailsafeDecision,
    FailsafeParams,
    FailsafeStatus,
    auto_disarm,
    battery_warning,
    datalink_loss,
    offboard_loss,
    scheduled_battery_action,
)
from sim.autopilot.mission_flight import (
    IDLE,
    LAND_OVER_M,
    MissionFrame,
    MissionRunner,
    MissionVehicle,
)
from sim.autopilot.mission_plan import (
    CMD_CHANGE_SPEED,
    CMD_LAND,
    CMD_RTL,
    CMD_TAKEOFF,
    CMD_WAYPOINT,
    MissionItem,
)
from sim.autopilot.params import make_params
from sim.autopilot.settings import AutopilotSettings

P = FailsafeParams(
    offboard_loss_timeout_s=1.0,
    offboard_loss_action=5.0,
    datalink_loss_timeout_s=10.0,
    datalink_loss_action=1.0,
    low_battery_action=3.0,
    battery_action_delay_s=5.0,
    disarm_landed_s=2.0,
    disarm_preflight_s=10.0,
    thresholds=Thresholds(0.15, 0.07, 0.05),
)
"""The defaults of `AutopilotSettings` (hold on offboard and datalink loss, return then land)."""

FLYING = FailsafeStatus(
    system_id=1,
    now_s=100.0,
    mode=FlightMode.OFFBOARD,
    armed=True,
    landed=False,
    armed_at_s=10.0,
    landed_at_s=None,
    last_setpoint_s=99.5,
    last_client_heartbeat_s=99.0,
    gcs_lost=False,
    battery_action_due=None,
    battery_warning=BatteryWarning.NONE,
    battery_remaining=0.8,
)
"""A vehicle in the air in OFFBOARD with setpoints and a client heartbeat: no failsafe due."""

ON_GROUND = replace(FLYING, mode=FlightMode.HOLD, landed=True)


def test_failsafe_params_read_the_px4_names() -> None:
    assert FailsafeParams.of(lambda name: make_params(AutopilotSettings())[name].value) == P
    s = AutopilotSettings(
        offboard_loss_timeout_s=1.5,
        offboard_loss_action="land",
        gcs_loss_timeout_s=7.0,
        gcs_loss_action="none",
        low_battery_action="land",
        battery_action_delay_s=4.0,
        disarm_after_land_s=3.0,
        disarm_preflight_s=11.0,
        battery_low_thr=0.2,
        battery_crit_thr=0.1,
        battery_emergen_thr=0.04,
    )
    params = make_params(s)
    assert FailsafeParams.of(lambda name: params[name].value) == FailsafeParams(
        1.5, 4.0, 7.0, 0.0, 2.0, 4.0, 3.0, 11.0, Thresholds(0.2, 0.1, 0.04)
    )


def test_nothing_is_due_for_a_vehicle_flying_as_it_should() -> None:
    assert all(check(FLYING, P) is None for check in failsafes.CHECKS)
    assert failsafes.CHECKS == (offboard_loss, datalink_loss, scheduled_battery_action, auto_disarm)


@pytest.mark.parametrize(("action", "mode"), [(5.0, FlightMode.HOLD), (4.0, FlightMode.LAND)])
def test_offboard_loss_after_com_of_loss_t_takes_com_obl_rc_act(
    action: float, mode: FlightMode
) -> None:
    p = replace(P, offboard_loss_action=action)
    assert offboard_loss(replace(FLYING, last_setpoint_s=99.0), p) is None, "1 s: not yet"
    assert offboard_loss(replace(FLYING, last_setpoint_s=98.9, mode=FlightMode.HOLD), p) is None
    assert offboard_loss(replace(FLYING, last_setpoint_s=98.9, armed=False), p) is None
    assert offboard_loss(replace(FLYING, last_setpoint_s=98.9), p) == FailsafeDecision(
        mode=mode,
        reason="offboard loss",
        statustext=(mavlink2.MAV_SEVERITY_WARNING, f"Offboard lost: {mode.value}"),
    )


def test_datalink_loss_after_com_dl_loss_t_marks_the_gcs_lost_and_takes_nav_dll_act() -> None:
    silent = replace(FLYING, mode=FlightMode.HOLD, last_client_heartbeat_s=89.9)
    said = (mavlink2.MAV_SEVERITY_CRITICAL, "Connection to ground station lost")
    assert datalink_loss(replace(silent, last_client_heartbeat_s=90.0), P) is None, "10 s"
    assert datalink_loss(replace(silent, last_client_heartbeat_s=None), P) is None, "none heard"
    assert datalink_loss(replace(silent, gcs_lost=True), P) is None, "declared once"
    to_land = datalink_loss(silent, replace(P, datalink_loss_action=3.0))
    assert to_land == FailsafeDecision(
        mode=FlightMode.LAND, reason="datalink loss", statustext=said, gcs_lost=True
    )
    # Lost but no mode change: already holding, landing, on the ground, or NAV_DLL_ACT 0.
    for status, p in [
        (silent, P),
        (replace(silent, mode=FlightMode.LAND), P),
        (replace(silent, mode=FlightMode.LAND), replace(P, datalink_loss_action=3.0)),
        (replace(silent, mode=FlightMode.OFFBOARD, landed=True), P),
        (replace(silent, mode=FlightMode.OFFBOARD), replace(P, datalink_loss_action=0.0)),
    ]:
        decision = datalink_loss(status, p)
        assert decision is not None and decision.gcs_lost and decision.statustext == said
        assert decision.mode is None
    in_offboard = datalink_loss(replace(silent, mode=FlightMode.OFFBOARD), P)
    assert in_offboard is not None and in_offboard.mode is FlightMode.HOLD


def test_low_battery_is_a_warning_only() -> None:
    d = battery_warning(BatteryWarning.LOW, FLYING, P)
    assert d == FailsafeDecision(statustext=(mavlink2.MAV_SEVERITY_WARNING, LOW_BATTERY_TEXT))


def test_critical_and_emergency_battery_schedule_the_action_com_bat_act_t_ahead() -> None:
    crit = battery_warning(BatteryWarning.CRITICAL, FLYING, P)
    assert crit == FailsafeDecision(
        statustext=(
            mavlink2.MAV_SEVERITY_CRITICAL,
            "Critical battery level, executing Return in 5 seconds",
        ),
        battery_action_due=(FlightMode.RTL, 105.0),
    )
    returning = replace(FLYING, mode=FlightMode.RTL)
    emerg = battery_warning(
        BatteryWarning.EMERGENCY, returning, replace(P, battery_action_delay_s=-1)
    )
    assert emerg.battery_action_due == (FlightMode.LAND, 100.0), "a land interrupts a return"
    assert emerg.statustext == (
        mavlink2.MAV_SEVERITY_EMERGENCY,
        "Dangerous battery level, executing Land in 0 seconds",
    )


@pytest.mark.parametrize(
    ("level", "status", "act", "text"),
    [
        (BatteryWarning.CRITICAL, replace(FLYING, mode=FlightMode.RTL), 3.0, "return now"),
        (BatteryWarning.CRITICAL, replace(FLYING, mode=FlightMode.LAND), 1.0, "return now"),
        (BatteryWarning.EMERGENCY, replace(FLYING, mode=FlightMode.LAND), 3.0, "land now"),
        (BatteryWarning.EMERGENCY, ON_GROUND, 3.0, "land now"),
        (BatteryWarning.CRITICAL, FLYING, 0.0, "return now"),
    ],
)
def test_battery_action_is_not_scheduled_when_moot(
    level: BatteryWarning, status: FailsafeStatus, act: float, text: str
) -> None:
    d = battery_warning(level, status, replace(P, low_battery_action=act))
    assert d.battery_action_due is None and d.mode is None
    assert d.statustext is not None and d.statustext[1].endswith(text)


def test_a_scheduled_battery_action_is_taken_when_due_and_then_forgotten() -> None:
    due = replace(
        FLYING, battery_action_due=(FlightMode.RTL, 105.0), battery_warning=BatteryWarning.CRITICAL
    )
    assert scheduled_battery_action(replace(due, now_s=104.99), P) is None
    assert scheduled_battery_action(replace(due, now_s=105.0), P) == FailsafeDecision(
        mode=FlightMode.RTL, reason="battery critical", drop_battery_action=True
    )
    for moot in (replace(due, now_s=106.0, landed=True), replace(due, mode=FlightMode.LAND)):
        d = scheduled_battery_action(replace(moot, now_s=106.0), P)
        assert d is not None and d.drop_battery_action and d.mode is None


def test_auto_disarm_after_com_disarm_land_or_com_disarm_prflt() -> None:
    touched = replace(ON_GROUND, landed_at_s=98.0)
    assert auto_disarm(touched, P) == FailsafeDecision(disarm=True, reason="landed")
    assert auto_disarm(replace(touched, now_s=99.9), P) is None
    assert auto_disarm(replace(touched, armed=False), P) is None
    assert auto_disarm(replace(touched, now_s=1e6), replace(P, disarm_landed_s=0.0)) is None
    never_flew = replace(ON_GROUND, armed_at_s=90.0)
    assert auto_disarm(never_flew, P) == FailsafeDecision(
        disarm=True, reason="no takeoff after arming"
    )
    assert auto_disarm(replace(never_flew, armed_at_s=90.1), P) is None
    assert auto_disarm(replace(never_flew, now_s=1e6), replace(P, disarm_preflight_s=0.0)) is None
    assert auto_disarm(replace(never_flew, landed=False), P) is None


# -- mission flight -----------------------------------------------------------------------------

FRAME = MissionFrame(PX4_SITL_ORIGIN, np.array([100.0, -50.0]), 0.0)
"""Local NED origin at scenario (100, -50) m; the ground at NED down 0."""
REL = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
AMSL = mavlink2.MAV_FRAME_GLOBAL_INT


def item(command: int, north_m: float = 0.0, east_m: float = 0.0, **kw: Any) -> MissionItem:
    """An item at local NED (north_m, east_m), at `z` (10 m above home unless told)."""
    fix = scenario_to_geodetic(
        np.array([east_m, north_m]) + FRAME.origin_xy_m, 0.0, FRAME.geo_origin
    )
    fields: dict[str, Any] = dict(seq=0, frame=REL, command=command, autocontinue=1)
    fields |= dict(param1=0.0, param2=0.0, param3=0.0, param4=math.nan, z=10.0)
    fields |= dict(x=round(fix.lat_deg * 1e7), y=round(fix.lon_deg * 1e7)) | kw
    return MissionItem(**fields)


def at(*ned: float, now_s: float = 0.0, landed: bool = False) -> MissionVehicle:
    return MissionVehicle(
        now_s=now_s,
        position_ned_m=np.array(ned, dtype=float),
        landed=landed,
        home_ned_m=np.array([0.0, 0.0, -2.0]),
        cruise_mps=5.0,
        acceptance_radius_m=2.0,
        altitude_radius_m=0.8,
    )


def runner(*items: MissionItem) -> MissionRunner:
    r = MissionRunner(FRAME)
    r.set_plan(list(items))
    r.resume(np.zeros(3))
    r.events.clear()
    return r


def target_of(decision: Any) -> list[float]:
    assert decision.guidance is not None
    return [round(float(x), 2) for x in decision.guidance.setpoint.position_ned_m]


def test_item_targets_in_the_relative_and_absolute_frames_and_without_a_position() -> None:
    home, start = np.array([0.0, 0.0, -2.0]), np.array([7.0, 8.0, -9.0])
    rel = FRAME.target_ned(item(CMD_WAYPOINT, 30.0, -20.0, z=15.0), start, home)
    assert rel == pytest.approx([30.0, -20.0, -17.0], abs=0.02), "15 m above home"
    amsl = PX4_SITL_ORIGIN.alt_amsl_m + 12.0
    absolute = FRAME.target_ned(item(CMD_WAYPOINT, 30.0, -20.0, frame=AMSL, z=amsl), start, home)
    assert absolute == pytest.approx([30.0, -20.0, -12.0], abs=0.02), "12 m above the ground"
    here = FRAME.target_ned(item(CMD_TAKEOFF, x=0, y=0, z=5.0), start, home)
    assert here.tolist() == [7.0, 8.0, -7.0]


def test_an_empty_plan_idles() -> None:
    assert runner().fly(at(0.0, 0.0, -5.0)) is IDLE


def test_takeoff_climbs_then_the_next_item_takes_over_in_the_same_step() -> None:
    r = runner(
        item(CMD_TAKEOFF, x=0, y=0, z=10.0),
        item(CMD_CHANGE_SPEED, param2=3.0),
        item(CMD_WAYPOINT, 30.0, 40.0, param4=90.0),
    )
    on_ground = r.fly(at(0.0, 0.0, 0.0, landed=True))
    assert target_of(on_ground) == [0.0, 0.0, -12.0] and on_ground.guidance is not None
    assert on_ground.guidance.max_speed_mps is None and r.events == []
    d = r.fly(at(0.0, 0.0, -11.5))
    assert r.current == 2 and r.events == [
        ("reached", 0),
        ("current", 1),
        ("reached", 1),
        ("current", 2),
    ]
    assert target_of(d) == [30.0, 40.0, -12.0]
    assert d.guidance is not None and d.guidance.max_speed_mps == 3.0, "DO_CHANGE_SPEED"
    assert d.guidance.setpoint.yaw_rad == pytest.approx(math.pi / 2)


def test_a_waypoint_is_reached_in_its_radius_and_left_after_its_hold_time() -> None:
    r = runner(item(CMD_WAYPOINT, 30.0, 0.0, param1=2.0), item(CMD_WAYPOINT, 0.0, 30.0, param2=5.0))
    outside = r.fly(at(27.0, 0.0, -12.0, now_s=1.0))
    assert target_of(outside) == [30.0, 0.0, -12.0] and r.current == 0
    assert outside.guidance is not None and outside.guidance.max_speed_mps == 5.0, "cruise"
    too_low = r.fly(at(29.0, 0.0, -11.0, now_s=2.0))
    assert r.current == 0 and target_of(too_low) == [30.0, 0.0, -12.0], "1 m low: not reached"
    r.fly(at(29.0, 0.0, -12.0, now_s=3.0))
    assert r.current == 0, "holding 2 s"
    d = r.fly(at(29.0, 0.0, -12.0, now_s=5.0))
    assert r.events == [("reached", 0), ("current", 1)]
    assert target_of(d) == [0.0, 30.0, -12.0]
    r.fly(at(3.0, 26.0, -12.0, now_s=6.0))
    assert r.current == 1 and not r.finished, "5 m from it, param2 = 5: not inside"
    hold = r.fly(at(3.0, 27.0, -12.0, now_s=7.0))
    assert r.finished and r.events[-1] == ("reached", 1)
    assert target_of(hold) == [3.0, 27.0, -12.0], "complete: holds where it is"
    assert r.fly(at(3.0, 27.0, 0.0, now_s=8.0, landed=True)) is IDLE


def test_a_complete_mission_starts_again_from_its_first_item() -> None:
    r = runner(item(CMD_WAYPOINT, 1.0, 0.0))
    r.fly(at(0.0, 0.0, -12.0))
    assert r.finished
    r.resume(np.array([0.0, 0.0, -12.0]))
    assert (r.current, r.finished, r.events[-1]) == (0, False, ("current", 0))


def test_an_rtl_item_asks_for_rtl() -> None:
    r = runner(item(CMD_RTL, x=0, y=0))
    d = r.fly(at(5.0, 5.0, -12.0))
    assert (d.mode, d.reason, d.guidance) == (FlightMode.RTL, "mission: return to launch", None)
    assert r.finished and r.events == [("reached", 0)]


def test_a_land_item_flies_over_its_point_then_descends_and_is_reached_on_touchdown() -> None:
    r = runner(item(CMD_LAND, 20.0, 0.0, z=0.0))
    far = r.fly(at(0.0, 0.0, -12.0))
    assert target_of(far) == [20.0, 0.0, -12.0] and not r.landing, "at the present altitude"
    over = r.fly(at(20.0 - LAND_OVER_M + 0.01, 0.0, -12.0))
    assert over.guidance is None and over.land_xy_ned_m is not None and r.landing
    assert over.land_xy_ned_m == pytest.approx([20.0, 0.0], abs=0.02)
    drifted = r.fly(at(17.0, 0.0, -5.0))
    assert drifted.land_xy_ned_m is not None, "once descending it keeps descending"
    assert r.fly(at(17.0, 0.0, 0.0, landed=True)) is IDLE and not r.finished
    r.touched_down(np.array([17.0, 0.0, 0.0]))
    assert r.finished and not r.landing and r.events == [("reached", 0)]
    assert r.fly(at(17.0, 0.0, 0.0, landed=True)) is IDLE
