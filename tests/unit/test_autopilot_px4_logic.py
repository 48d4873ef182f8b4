"""The pure parts of the simulated vehicle's PX4 behaviour: the energy model and PX4's battery
warning levels, the low-battery actions, the RTL legs, the fall of a disarmed vehicle, mission
item checks, and the settings' and scenario's errors."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from isac_mission.config import parse_scenario
from isac_mission.errors import ConfigError
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.battery import Battery, BatterySettings, BatteryWarning, Thresholds
from sim.autopilot.failsafes import battery_action
from sim.autopilot.guidance import GRAVITY_MPS2, fall_step
from sim.autopilot.mission_plan import MissionItem, check_item
from sim.autopilot.rtl import Rtl, RtlPhase
from sim.autopilot.settings import AutopilotSettings
from sim.vehicle import VehicleState

PX4_THRESHOLDS = Thresholds(0.15, 0.07, 0.05)


def test_energy_drawn_is_power_times_time_with_the_speed_and_climb_terms() -> None:
    b = Battery(BatterySettings(capacity_wh=100.0, min_remaining=0.0))
    for _ in range(3600):  # one hour at 1 s steps, hovering armed
        b.step(1.0, True, 0.0, 0.0, PX4_THRESHOLDS)
    # 250 W for 1 h would be 250 Wh: a 100 Wh pack is empty after 100.
    assert b.energy_drawn_wh == pytest.approx(100.0)
    assert b.remaining == 0.0
    b = Battery(BatterySettings(capacity_wh=100.0))
    b.step(36.0, True, 10.0, 2.0, PX4_THRESHOLDS)  # 0.01 h at 10 m/s climbing 2 m/s
    assert b.power_w == pytest.approx(250.0 + 4.0 * 10.0 + 30.0 * 2.0)
    assert b.energy_drawn_wh == pytest.approx(3.5)
    assert b.remaining == pytest.approx(1.0 - 3.5 / 100.0)
    assert b.power_for(True, 0.0, -3.0) == 250.0, "descending costs no more than hovering"
    assert b.power_for(False, 10.0, 2.0) == 5.0, "disarmed: avionics only"


def test_charge_stops_at_the_sitl_floor_by_default() -> None:
    b = Battery(BatterySettings(capacity_wh=1.0))
    for _ in range(100):  # 250 W for 100 s: 6.9 Wh asked of a 1 Wh pack
        b.step(1.0, True, 0.0, 0.0, PX4_THRESHOLDS)
    assert b.remaining == pytest.approx(0.5)
    assert b.energy_drawn_wh == pytest.approx(0.5)
    assert b.warning is BatteryWarning.NONE


def test_voltage_falls_linearly_with_charge_and_current_is_power_over_voltage() -> None:
    b = Battery(BatterySettings(start_remaining=0.5))
    assert b.voltage_v == pytest.approx(4 * (3.6 + 0.5 * 0.45))
    b.step(1.0, True, 0.0, 0.0, PX4_THRESHOLDS)
    assert b.current_a == pytest.approx(250.0 / b.voltage_v)
    assert b.time_remaining_s == pytest.approx(3600.0 * b.remaining * 80.0 / 250.0)


def test_warning_levels_rise_once_each_and_never_fall() -> None:
    b = Battery(BatterySettings(capacity_wh=1.0, start_remaining=0.2, min_remaining=0.0))
    rises = []
    for _ in range(400):  # 250 W drains 1 Wh in 14.4 s; 0.1 s steps
        level = b.step(0.1, True, 0.0, 0.0, PX4_THRESHOLDS)
        if level is not None:
            rises.append((level, b.remaining))
    assert [lvl for lvl, _ in rises] == [
        BatteryWarning.LOW,
        BatteryWarning.CRITICAL,
        BatteryWarning.EMERGENCY,
    ]
    step = 250.0 * 0.1 / 3600.0  # one step's share of the 1 Wh pack
    for (_, remaining), threshold in zip(rises, (0.15, 0.07, 0.05), strict=True):
        assert threshold - step <= remaining < threshold
    assert b.warning is BatteryWarning.EMERGENCY


@pytest.mark.parametrize(
    ("act", "critical", "emergency"),
    [
        (0, None, None),
        (1, FlightMode.RTL, FlightMode.RTL),
        (2, FlightMode.LAND, FlightMode.LAND),
        (3, FlightMode.RTL, FlightMode.LAND),
    ],
)
def test_com_low_bat_act_maps_levels_to_px4_actions(
    act: int, critical: FlightMode | None, emergency: FlightMode | None
) -> None:
    assert battery_action(BatteryWarning.LOW, act) is None
    assert battery_action(BatteryWarning.CRITICAL, act) is critical
    assert battery_action(BatteryWarning.EMERGENCY, act) is emergency


def test_rtl_return_altitude_is_the_higher_of_rtl_return_alt_and_the_present_one() -> None:
    home = np.array([0.0, 0.0, 0.0])
    low = Rtl.start(np.array([50.0, 0.0, -10.0]), home, 60.0, 30.0, 0.0, 5.0)
    assert (low.return_down_m, low.descend_down_m, low.phase) == (-60.0, -30.0, RtlPhase.CLIMB)
    high = Rtl.start(np.array([50.0, 0.0, -100.0]), home, 60.0, 30.0, 0.0, 5.0)
    assert (high.return_down_m, high.descend_down_m) == (-100.0, -30.0)
    below_descend = Rtl.start(np.array([50.0, 0.0, -5.0]), home, 20.0, 30.0, 0.0, 5.0)
    assert below_descend.descend_down_m == -20.0, "never descends to above the return altitude"


def test_rtl_legs_follow_in_order() -> None:
    rtl = Rtl.start(np.array([50.0, 0.0, -10.0]), np.zeros(3), 20.0, 8.0, 2.0, 5.0)
    at = VehicleState(position_ned_m=np.array([50.0, 0.0, -10.0]))
    g = rtl.guidance(at, 0.0)
    assert g is not None and g.setpoint.position_ned_m.tolist() == [50.0, 0.0, -20.0]
    g = rtl.guidance(VehicleState(position_ned_m=np.array([50.0, 0.0, -20.0])), 1.0)
    assert rtl.phase is RtlPhase.RETURN and g is not None and g.max_speed_mps == 5.0
    assert g.setpoint.position_ned_m.tolist() == [0.0, 0.0, -20.0]
    g = rtl.guidance(VehicleState(position_ned_m=np.array([0.2, 0.0, -20.0])), 2.0)
    assert rtl.phase is RtlPhase.DESCEND and g is not None
    assert g.setpoint.position_ned_m.tolist() == [0.0, 0.0, -8.0]
    rtl.guidance(VehicleState(position_ned_m=np.array([0.0, 0.0, -8.0])), 3.0)
    assert rtl.phase is RtlPhase.LOITER
    assert rtl.guidance(VehicleState(position_ned_m=np.array([0.0, 0.0, -8.0])), 4.9) is not None
    assert rtl.guidance(VehicleState(position_ned_m=np.array([0.0, 0.0, -8.0])), 5.0) is None
    assert rtl.phase is RtlPhase.LAND


def test_a_disarmed_vehicle_falls_under_gravity_and_stops_at_the_ground() -> None:
    s = VehicleState(position_ned_m=np.array([0.0, 0.0, -20.0]))
    t, dt = 0.0, 0.001
    while s.position_ned_m[2] < 0.0:
        s = fall_step(s, 0.0, dt)
        t += dt
    assert t == pytest.approx(math.sqrt(2 * 20.0 / GRAVITY_MPS2), abs=2 * dt)
    assert s.velocity_ned_mps.tolist() == [0.0, 0.0, 0.0]


def item(command: int, frame: int = 6, **kw: Any) -> MissionItem:
    fields: dict[str, Any] = dict(
        seq=0, frame=frame, command=command, autocontinue=1, param1=0.0, param2=0.0
    )
    fields |= dict(param3=0.0, param4=math.nan, x=473_977_000, y=85_456_000, z=10.0) | kw
    return MissionItem(**fields)


@pytest.mark.parametrize(
    ("it", "result"),
    [
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT), "MAV_MISSION_ACCEPTED"),
        (item(mavlink2.MAV_CMD_NAV_TAKEOFF, x=0, y=0), "MAV_MISSION_ACCEPTED"),
        (item(mavlink2.MAV_CMD_NAV_LAND, frame=0), "MAV_MISSION_ACCEPTED"),
        (item(mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=2), "MAV_MISSION_ACCEPTED"),
        (item(mavlink2.MAV_CMD_DO_CHANGE_SPEED, frame=2, param2=8.0), "MAV_MISSION_ACCEPTED"),
        (item(mavlink2.MAV_CMD_NAV_LOITER_TIME), "MAV_MISSION_UNSUPPORTED"),
        (item(mavlink2.MAV_CMD_DO_SET_SERVO), "MAV_MISSION_UNSUPPORTED"),
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT, frame=1), "MAV_MISSION_UNSUPPORTED_FRAME"),
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT, frame=10), "MAV_MISSION_UNSUPPORTED_FRAME"),
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT, param1=-1.0), "MAV_MISSION_INVALID_PARAM1"),
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT, param2=math.nan), "MAV_MISSION_INVALID_PARAM2"),
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT, x=910_000_000), "MAV_MISSION_INVALID_PARAM5_X"),
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT, y=-1_810_000_000), "MAV_MISSION_INVALID_PARAM6_Y"),
        (item(mavlink2.MAV_CMD_NAV_WAYPOINT, z=math.inf), "MAV_MISSION_INVALID_PARAM7"),
    ],
)
def test_mission_items_are_accepted_or_refused_naming_the_fault(
    it: MissionItem, result: str
) -> None:
    assert check_item(it) == getattr(mavlink2, result)


def test_mission_item_float_and_int_forms_agree() -> None:
    it = item(mavlink2.MAV_CMD_NAV_WAYPOINT)
    as_float = it.to_message((255, 0), False, as_int=False)
    assert as_float.x == pytest.approx(47.3977)
    assert MissionItem.from_message(as_float) == it
    assert MissionItem.from_message(it.to_message((255, 0), True, as_int=True)) == it


def test_bad_battery_settings_name_the_field() -> None:
    with pytest.raises(ConfigError, match="capacity_wh"):
        BatterySettings(capacity_wh=-1.0)
    with pytest.raises(ConfigError, match="cell_empty_v"):
        BatterySettings(cell_empty_v=4.2)
    with pytest.raises(ConfigError, match="battery_emergen_thr <= battery_crit_thr"):
        AutopilotSettings(battery_low_thr=0.05, battery_crit_thr=0.1)
    with pytest.raises(ConfigError, match="battery_action_delay_s"):
        AutopilotSettings(battery_action_delay_s=-1.0)


@pytest.mark.parametrize(
    ("battery", "expected"),
    [
        ({"capacity_wh_by_uav": {5: 2.0}}, "uavs.battery.capacity_wh_by_uav: no UAV 5 (M = 3)"),
        ({"capacity_wh_by_uav": {1: 0.0}}, "capacity_wh_by_uav: UAV 1"),
        ({"capacity_wh": 0}, "uavs.battery.capacity_wh"),
        ({"low_thr": 0.05, "critical_thr": 0.1}, "emergency_thr <= critical_thr <= low_thr"),
        ({"capacity": 3}, "uavs.battery.capacity: unknown key"),
    ],
)
def test_bad_scenario_battery_names_the_field(battery: dict[str, Any], expected: str) -> None:
    with pytest.raises(ConfigError) as err:
        parse_scenario({"uavs": {"battery": battery}}, "x.yaml")
    assert expected in str(err.value)


def test_scenario_battery_reaches_each_vehicle() -> None:
    from sim.world_assembly import autopilot_settings
    from sim.world_options import WorldOptions

    s = parse_scenario({"uavs": {"battery": {"capacity_wh_by_uav": {1: 2.5}}}}, "x.yaml")
    caps = [autopilot_settings(s, WorldOptions(), m).battery.capacity_wh for m in range(3)]
    assert caps == [80.0, 2.5, 80.0]
    assert autopilot_settings(s, WorldOptions(), 1).battery.min_remaining == 0.5
    assert autopilot_settings(s, WorldOptions(), 0).cruise_speed_mps == s.v_max
