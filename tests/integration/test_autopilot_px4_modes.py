"""What ground stations expect of a PX4 vehicle, over real UDP MAVLink 2 with a pymavlink client:
AUTO.RTL (by mode and by MAV_CMD_NAV_RETURN_TO_LAUNCH), MAV_CMD_DO_REPOSITION in HOLD, force
disarm in the air, VFR_HUD, BATTERY_STATUS and PX4's low-battery failsafe.

The client listens as PX4's offboard client does (tests/support/autopilot_client.py); the
simulation runs at `SIM_SPEED` x real time in its own thread; tests wait for events with generous
wall-clock deadlines and check the vehicle's snapshots (`Autopilot.state`) and its messages.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from isac_mission.frames import ned_to_geodetic
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.battery import BatterySettings
from sim.autopilot.endpoint import Autopilot
from tests.support.autopilot_client import (
    HOLD,
    LAND,
    TAKEOFF_ALT_M,
    Client,
    enter_offboard,
    take_off,
)
from tests.support.sim_harness import wait_until

pytestmark = pytest.mark.timeout(120)

RTL = FlightMode.RTL.px4_custom_mode
RETURN_ALT_M = 12.0
DESCEND_ALT_M = 8.0


def fly_out(ap: Autopilot, client: Client, ned: tuple[float, float, float]) -> None:
    """Take off, fly offboard to `ned` and wait there."""
    take_off(ap, client)
    enter_offboard(ap, client, ned)
    wait_until(lambda: math.dist(tuple(ap.state.position_ned_m), ned) < 0.5, 30.0, "out")


def watch_until_disarmed(ap: Autopilot, timeout_s: float = 60.0) -> list[tuple[float, ...]]:
    """Sample (time, north, east, down, mode is RTL) until the vehicle is landed and disarmed."""
    samples: list[tuple[float, ...]] = []
    deadline = time.monotonic() + timeout_s
    while True:
        s = ap.state
        samples.append((s.time_s, *s.position_ned_m, float(s.mode is FlightMode.RTL)))
        if s.landed and not s.armed:
            return samples
        if time.monotonic() > deadline:
            raise AssertionError(f"not landed and disarmed within {timeout_s} s: {s}")
        time.sleep(0.01)


def check_return(samples: list[tuple[float, ...]], home: tuple[float, float]) -> None:
    """The return climbed to RETURN_ALT_M, kept it while away from home, and came down at home."""
    heights = [-s[3] for s in samples]
    assert max(heights) == pytest.approx(RETURN_ALT_M, abs=0.6)
    away = [-s[3] for s in samples if math.hypot(s[1] - home[0], s[2] - home[1]) > 5.0]
    late = away[len(away) // 2 :]  # after the climb, on the way home
    assert late and all(abs(h - RETURN_ALT_M) < 0.6 for h in late)
    end = samples[-1]
    assert math.hypot(end[1] - home[0], end[2] - home[1]) < 1.0
    assert -end[3] < 0.05


def test_rtl_by_mode_climbs_returns_home_lands_and_disarms(fly) -> None:
    _runner, ap, client = fly(rtl_return_alt_m=RETURN_ALT_M, rtl_descend_alt_m=DESCEND_ALT_M)
    fly_out(ap, client, (30.0, -20.0, -TAKEOFF_ALT_M))
    home = (0.0, 0.0)  # where it armed: the local origin
    assert client.set_mode(FlightMode.RTL) == mavlink2.MAV_RESULT_ACCEPTED
    client.stop_stream()
    client.recv("HEARTBEAT", lambda m: m.custom_mode == RTL)
    samples = watch_until_disarmed(ap)
    check_return(samples, home)
    hb = client.recv("HEARTBEAT", lambda m: not m.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
    assert hb.custom_mode == RTL
    ess = client.recv("EXTENDED_SYS_STATE")
    assert ess.landed_state == mavlink2.MAV_LANDED_STATE_ON_GROUND


def test_return_to_launch_command_is_denied_on_the_ground_and_flies_rtl_in_the_air(fly) -> None:
    _runner, ap, client = fly(rtl_return_alt_m=RETURN_ALT_M, rtl_descend_alt_m=DESCEND_ALT_M)
    rtl = mavlink2.MAV_CMD_NAV_RETURN_TO_LAUNCH
    assert client.command(rtl) == mavlink2.MAV_RESULT_DENIED
    fly_out(ap, client, (-25.0, 15.0, -TAKEOFF_ALT_M))
    assert client.command(rtl) == mavlink2.MAV_RESULT_ACCEPTED
    client.stop_stream()
    assert ap.state.mode is FlightMode.RTL
    check_return(watch_until_disarmed(ap), (0.0, 0.0))


def test_reposition_flies_to_the_point_at_the_given_speed_in_hold(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    s = ap.settings
    target_ned = np.array([40.0, 30.0, -12.0])
    geo = ned_to_geodetic(target_ned, s.local_origin_xy_m, s.geo_origin)
    speed_mps = 3.0
    client.clear("COMMAND_ACK")
    client.send(
        mavlink2.MAVLink_command_int_message(
            1,
            1,
            mavlink2.MAV_FRAME_GLOBAL,
            mavlink2.MAV_CMD_DO_REPOSITION,
            0,
            0,
            speed_mps,
            mavlink2.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE,
            0.0,
            math.nan,
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            geo.alt_amsl_m,
        )
    )
    ack = client.recv("COMMAND_ACK", lambda m: m.command == mavlink2.MAV_CMD_DO_REPOSITION)
    assert ack.result == mavlink2.MAV_RESULT_ACCEPTED
    assert ap.state.mode is FlightMode.HOLD
    client.recv("HEARTBEAT", lambda m: m.custom_mode == HOLD)
    top_speed = 0.0

    def arrived() -> bool:
        nonlocal top_speed
        st = ap.state
        top_speed = max(top_speed, float(np.hypot(*st.velocity_ned_mps[:2])))
        return bool(np.linalg.norm(st.position_ned_m - target_ned) < 0.3)

    wait_until(arrived, 60.0, "at the reposition target")
    assert top_speed == pytest.approx(speed_mps, abs=0.05)
    # It holds there (HOLD, still at the point some simulated seconds later).
    t0 = ap.state.time_s
    wait_until(lambda: ap.state.time_s > t0 + 5.0, 10.0, "5 s of simulation")
    assert ap.state.mode is FlightMode.HOLD
    assert np.linalg.norm(ap.state.position_ned_m - target_ned) < 0.3


def test_force_disarm_in_the_air_drops_the_vehicle_and_plain_disarm_is_denied(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    arm = mavlink2.MAV_CMD_COMPONENT_ARM_DISARM
    assert client.command(arm, 0) == mavlink2.MAV_RESULT_DENIED
    assert ap.state.armed and not ap.state.landed
    t0 = ap.state.time_s
    assert client.command(arm, 0, 21196) == mavlink2.MAV_RESULT_ACCEPTED
    assert not ap.state.armed
    wait_until(lambda: ap.state.landed, 10.0, "on the ground")
    fall_s = ap.state.time_s - t0
    # Free fall from TAKEOFF_ALT_M: sqrt(2 h / g) (plus up to a tick and the ACK's latency).
    assert fall_s == pytest.approx(math.sqrt(2 * TAKEOFF_ALT_M / 9.80665), abs=0.3)
    client.recv("HEARTBEAT", lambda m: not m.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
    client.clear("EXTENDED_SYS_STATE")
    ess = client.recv("EXTENDED_SYS_STATE")
    assert ess.landed_state == mavlink2.MAV_LANDED_STATE_ON_GROUND
    t1 = ap.state.time_s
    wait_until(lambda: ap.state.time_s > t1 + 3.0, 10.0, "3 s of simulation")
    assert ap.state.altitude_m == 0.0 and not ap.state.armed and ap.state.landed


def test_vfr_hud_matches_the_position_telemetry(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    client.stream(0xDC7, (0.0, 0.0, 0.0), (3.0, 4.0, -1.0))  # velocity only
    wait_until(lambda: client.set_mode(FlightMode.OFFBOARD) == 0, 10.0, "OFFBOARD accepted")
    wait_until(
        lambda: np.allclose(ap.state.velocity_ned_mps, (3.0, 4.0, -1.0), atol=0.01),
        20.0,
        "steady velocity",
    )
    # Messages sent while accelerating may still sit in the socket buffer: anchor on a
    # GLOBAL_POSITION_INT stamped after the steady state, then take a VFR_HUD sent after it
    # (one socket, in order, so every VFR_HUD queued before that GPI is dropped).
    steady_ms = ap.state.time_s * 1000.0
    gpi = client.recv("GLOBAL_POSITION_INT", lambda m: m.time_boot_ms >= steady_ms)
    client.clear("VFR_HUD")
    hud = client.recv("VFR_HUD")
    assert hud.groundspeed == pytest.approx(5.0, abs=0.05)
    assert hud.airspeed == pytest.approx(hud.groundspeed)
    assert hud.climb == pytest.approx(1.0, abs=0.05)
    assert hud.heading == round(gpi.hdg / 100) % 360
    assert hud.alt == pytest.approx(gpi.alt / 1000.0, abs=1.5)  # 1 m/s climb, one message apart
    assert 40 < hud.throttle < 70  # about half at hover, a little more climbing
    client.command(mavlink2.MAV_CMD_NAV_LAND)


def test_battery_status_and_sys_status_agree(fly) -> None:
    _runner, _ap, client = fly(battery=BatterySettings(capacity_wh=10.0, start_remaining=0.8))
    client.clear("BATTERY_STATUS")
    bs = client.recv("BATTERY_STATUS")
    ss = client.recv("SYS_STATUS")
    cells = [v for v in bs.voltages if v != 65535]
    assert len(cells) == 4
    assert sum(cells) == pytest.approx(ss.voltage_battery, abs=4)
    # 80 % charge: 3.6 + 0.8 * (4.05 - 3.6) V per cell.
    assert sum(cells) / 1000.0 == pytest.approx(4 * (3.6 + 0.8 * 0.45), abs=0.01)
    assert bs.battery_remaining == ss.battery_remaining == 80
    assert bs.current_battery == pytest.approx(ss.current_battery, abs=1)
    assert bs.charge_state == mavlink2.MAV_BATTERY_CHARGE_STATE_OK
    # Disarmed: 5 W of avionics at 15.84 V is 0.32 A (31.6 cA).
    assert bs.current_battery == pytest.approx(5.0 / 15.84 * 100, abs=1)


def statustexts(client: Client, n: int) -> list[tuple[int, str]]:
    """The next `n` texts, chunked ones (MAVLink 2 id, chunk_seq) joined."""
    out: list[tuple[int, str]] = []
    chunks: list[str] = []
    while len(out) < n:
        m = client.recv("STATUSTEXT", timeout_s=60.0)
        text = m.text if isinstance(m.text, str) else m.text.decode()
        if m.id == 0:
            out.append((int(m.severity), text))
            continue
        chunks.append(text)
        if len(text) < 50:
            out.append((int(m.severity), "".join(chunks)))
            chunks = []
    return out


def test_low_battery_warns_then_returns_at_the_critical_level(fly) -> None:
    _runner, ap, client = fly(
        battery=BatterySettings(capacity_wh=4.0, min_remaining=0.0),
        battery_low_thr=0.85,
        battery_crit_thr=0.75,
        battery_emergen_thr=0.05,
        battery_action_delay_s=1.0,
        rtl_return_alt_m=RETURN_ALT_M,
        rtl_descend_alt_m=DESCEND_ALT_M,
    )
    fly_out(ap, client, (20.0, 0.0, -TAKEOFF_ALT_M))
    texts = statustexts(client, 2)
    assert texts[0] == (mavlink2.MAV_SEVERITY_WARNING, "Low battery level, return advised")
    assert texts[1] == (
        mavlink2.MAV_SEVERITY_CRITICAL,
        "Critical battery level, executing Return in 1 seconds",
    )
    client.recv("HEARTBEAT", lambda m: m.custom_mode == RTL, timeout_s=20.0)
    bs = client.recv("BATTERY_STATUS", lambda m: m.charge_state >= 3)
    assert bs.charge_state == mavlink2.MAV_BATTERY_CHARGE_STATE_CRITICAL
    client.clear("SYS_STATUS")
    ss = client.recv("SYS_STATUS")
    assert not ss.onboard_control_sensors_health & mavlink2.MAV_SYS_STATUS_SENSOR_BATTERY
    client.stop_stream()
    check_return(watch_until_disarmed(ap), (0.0, 0.0))
    assert ap.state.battery_remaining > 0.05


def test_emergency_battery_level_lands_where_it_is(fly) -> None:
    _runner, ap, client = fly(
        battery=BatterySettings(capacity_wh=1.0, min_remaining=0.0),
        battery_low_thr=0.8,
        battery_crit_thr=0.6,
        battery_emergen_thr=0.5,
        battery_action_delay_s=0.0,
        rtl_return_alt_m=60.0,
    )
    take_off(ap, client)
    client.recv("HEARTBEAT", lambda m: m.custom_mode == RTL, timeout_s=30.0)
    client.recv("HEARTBEAT", lambda m: m.custom_mode == LAND, timeout_s=30.0)
    texts = [t for _, t in statustexts(client, 3)]
    assert texts[2] == "Dangerous battery level, executing Land in 0 seconds"
    wait_until(lambda: ap.state.landed and not ap.state.armed, 60.0, "landed and disarmed")


def test_reposition_without_change_mode_is_ignored_outside_hold(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    enter_offboard(ap, client, (0.0, 0.0, -TAKEOFF_ALT_M))
    s = ap.settings
    geo = ned_to_geodetic(np.array([30.0, 0.0, -8.0]), s.local_origin_xy_m, s.geo_origin)
    result = client.command(
        mavlink2.MAV_CMD_DO_REPOSITION, -1, 0, 0, math.nan, geo.lat_deg, geo.lon_deg, geo.alt_amsl_m
    )
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    t0 = ap.state.time_s
    wait_until(lambda: ap.state.time_s > t0 + 3.0, 10.0, "3 s of simulation")
    assert ap.state.mode is FlightMode.OFFBOARD
    assert math.dist(tuple(ap.state.position_ned_m), (0.0, 0.0, -TAKEOFF_ALT_M)) < 0.3
