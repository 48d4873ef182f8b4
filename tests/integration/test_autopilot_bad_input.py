"""The simulated vehicle over real UDP MAVLink 2, driven by pymavlink clients: bad input (garbage, bad CRC, unknown ids,
NaN, out-of-area and below-ground setpoints, another system's setpoints).

Each client listens as PX4's offboard client does (`udpin:127.0.0.1:PORT`, the vehicle sending to
PORT) and answers the vehicle from there (tests/support/autopilot_client.py). The simulation runs
at `SIM_SPEED` x real time in its own thread; tests wait for events with generous wall-clock
deadlines.
"""

from __future__ import annotations

import math

import pytest

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from tests.support.autopilot_client import (
    HOLD,
    MASK_POSITION_YAW,
    OFFBOARD,
    TAKEOFF_ALT_M,
    enter_offboard,
    mavlink2_frame,
    near,
    raw_send,
    take_off,
)
from tests.support.sim_harness import wait_until

pytestmark = pytest.mark.timeout(90)


def test_garbage_bad_crc_unknown_ids_are_counted_and_dropped_in_flight(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    hold = (5.0, 5.0, -TAKEOFF_ALT_M)
    enter_offboard(ap, client, hold)
    wait_until(lambda: near(ap, hold, 0.3), 20.0, "at the setpoint")

    raw_send(ap, b"\x00\x01 this is not mavlink \xff" * 4)
    good = client.position_target(MASK_POSITION_YAW, (100.0, 100.0, -TAKEOFF_ALT_M))
    packed = bytearray(good.pack(mavlink2.MAVLink(None, 255, 190)))
    packed[-1] ^= 0xFF  # corrupt the CRC: a setpoint that must not be obeyed
    raw_send(ap, bytes(packed))
    raw_send(ap, mavlink2_frame(0xABCDE, b"\x01\x02\x03\x04"))
    raw_send(ap, bytes(packed[:9]))  # truncated header
    wait_until(
        lambda: all(
            ap.rejected[r] >= 1 for r in ("garbage", "bad_crc", "unknown_message", "truncated")
        ),
        10.0,
        f"all four counted (so far {ap.rejected})",
    )
    assert ap.rejected["bad_crc"] == 1 and ap.rejected["unknown_message"] == 1
    t0 = ap.state.time_s
    wait_until(lambda: ap.state.time_s > t0 + 2.0, 10.0, "2 s of simulation time")
    assert ap.state.mode is FlightMode.OFFBOARD and near(ap, hold, 0.3), "kept flying the setpoint"
    client.recv("HEARTBEAT", lambda m: m.custom_mode == OFFBOARD)


def test_nan_setpoint_is_ignored_and_the_vehicle_keeps_its_last_target(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    hold = (0.0, 0.0, -TAKEOFF_ALT_M)
    enter_offboard(ap, client, hold)
    client.stream(MASK_POSITION_YAW, (math.nan, 3.0, -TAKEOFF_ALT_M))
    wait_until(lambda: ap.rejected["non_finite_setpoint"] >= 10, 10.0, "NaN setpoints counted")
    # NaN setpoints do not feed the stream either: the vehicle falls back to HOLD where it is.
    client.recv("HEARTBEAT", lambda m: m.custom_mode == HOLD)
    assert near(ap, hold, 0.2) and ap.state.armed and not ap.state.landed
    client.stream(MASK_POSITION_YAW, (4.0, 0.0, -TAKEOFF_ALT_M))
    wait_until(lambda: client.set_mode(FlightMode.OFFBOARD) == 0, 10.0, "OFFBOARD again")
    wait_until(lambda: near(ap, (4.0, 0.0, -TAKEOFF_ALT_M), 0.3), 20.0, "flies again")


def test_out_of_area_setpoint_is_clamped_to_the_area(fly) -> None:
    _runner, ap, client = fly(area_min_xy_m=(-30.0, -30.0), area_max_xy_m=(30.0, 30.0))
    take_off(ap, client)
    enter_offboard(ap, client, (0.0, 0.0, -TAKEOFF_ALT_M))
    client.stream(MASK_POSITION_YAW, (10.0, 500.0, -TAKEOFF_ALT_M))  # east 500 m: x = 500
    wait_until(lambda: ap.rejected["out_of_area"] >= 1, 10.0, "out of area counted")
    wait_until(
        lambda: (
            abs(ap.state.position_xy_m[0] - 30.0) < 0.1 and abs(ap.state.velocity_ned_mps[1]) < 0.01
        ),
        30.0,
        "stopped at the area boundary",
    )
    assert ap.state.position_xy_m[0] <= 30.0 + 1e-6
    assert ap.state.position_xy_m[1] == pytest.approx(10.0, abs=0.1)
    assert ap.state.mode is FlightMode.OFFBOARD


def test_below_ground_setpoint_is_clamped_to_the_minimum_altitude(fly) -> None:
    _runner, ap, client = fly(min_altitude_m=2.0)
    take_off(ap, client)
    enter_offboard(ap, client, (0.0, 0.0, -TAKEOFF_ALT_M))
    client.stream(MASK_POSITION_YAW, (0.0, 0.0, 5.0))  # 5 m below the ground
    wait_until(lambda: ap.rejected["below_ground"] >= 1, 10.0, "below ground counted")
    wait_until(
        lambda: abs(ap.state.altitude_m - 2.0) < 0.05 and abs(ap.state.velocity_ned_mps[2]) < 0.01,
        30.0,
        "settled at the minimum altitude",
    )
    assert ap.state.mode is FlightMode.OFFBOARD and not ap.state.landed and ap.state.armed


def test_setpoint_for_another_system_is_not_obeyed(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    hold = (0.0, 0.0, -TAKEOFF_ALT_M)
    enter_offboard(ap, client, hold)
    for _ in range(5):
        client.send(client.position_target(MASK_POSITION_YAW, (30.0, 0.0, -8.0), target_system=7))
    wait_until(lambda: ap.ignored["other_system"] >= 5, 10.0, "other-system setpoints ignored")
    t0 = ap.state.time_s
    wait_until(lambda: ap.state.time_s > t0 + 1.0, 10.0, "1 s of simulation time")
    assert near(ap, hold, 0.2)
