"""The simulated vehicle over real UDP MAVLink 2, driven by pymavlink clients: identity, telemetry and the MAVLink protocols
(commands, params, mission), the GCS link, handler errors.

Each client listens as PX4's offboard client does (`udpin:127.0.0.1:PORT`, the vehicle sending to
PORT) and answers the vehicle from there (tests/support/autopilot_client.py). The simulation runs
at `SIM_SPEED` x real time in its own thread; tests wait for events with generous wall-clock
deadlines.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import numpy as np
import pytest

from isac_mission.frames import scenario_to_geodetic
from isac_mission.mavwire.dialect import mavlink2
from sim.autopilot.params import ParamProtocol
from tests.support.autopilot_client import HOLD, TAKEOFF_ALT_M, Client, make_settings
from tests.support.sim_harness import wait_until

pytestmark = pytest.mark.timeout(90)


def test_vehicle_is_a_px4_quadrotor_with_system_id_index_plus_one(fly) -> None:
    _runner, ap, client = fly(index=2, local_origin_xy_m=(10.0, 5.0), spawn_xy_m=(30.0, -20.0))
    hb = client.recv("HEARTBEAT")
    assert hb.get_srcSystem() == 3 and hb.get_srcComponent() == 1
    assert hb.type == mavlink2.MAV_TYPE_QUADROTOR
    assert hb.autopilot == mavlink2.MAV_AUTOPILOT_PX4
    assert hb.base_mode & mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not hb.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    assert hb.custom_mode == HOLD
    # Local NED around the scenario point (10, 5): north = y - 5, east = x - 10, down = 0.
    lpn = client.recv("LOCAL_POSITION_NED")
    assert (lpn.x, lpn.y, lpn.z) == pytest.approx((-25.0, 20.0, 0.0), abs=1e-4)
    gpi = client.recv("GLOBAL_POSITION_INT")
    geo = scenario_to_geodetic(np.array([30.0, -20.0]), 0.0, ap.settings.geo_origin)
    assert gpi.lat == round(geo.lat_deg * 1e7) and gpi.lon == round(geo.lon_deg * 1e7)
    assert gpi.alt == round(geo.alt_amsl_m * 1000) and gpi.relative_alt == 0
    # 20 m south of the origin is 20 / R rad of latitude.
    assert geo.lat_deg - ap.settings.geo_origin.lat_deg == pytest.approx(
        math.degrees(-20.0 / 6_378_137.0), rel=1e-12
    )
    status = client.recv("SYS_STATUS")
    for bit in (mavlink2.MAV_SYS_STATUS_SENSOR_GPS, mavlink2.MAV_SYS_STATUS_PREARM_CHECK):
        assert status.onboard_control_sensors_present & bit
        assert status.onboard_control_sensors_enabled & bit
        assert status.onboard_control_sensors_health & bit
    ess = client.recv("EXTENDED_SYS_STATE")
    assert ess.landed_state == mavlink2.MAV_LANDED_STATE_ON_GROUND
    client.recv("HOME_POSITION")


def test_telemetry_rate_follows_simulation_time(fly) -> None:
    _runner, _ap, client = fly(telemetry_rate_hz=20.0)
    first = client.recv("LOCAL_POSITION_NED")
    times = [first.time_boot_ms]
    while len(times) < 41:
        times.append(client.recv("LOCAL_POSITION_NED").time_boot_ms)
    # 40 intervals at 20 Hz of simulation time: 2 s of time_boot_ms, whatever the wall rate.
    assert times[-1] - times[0] == pytest.approx(2000, abs=20)


def test_commands_are_answered_with_honest_acks(fly) -> None:
    _runner, ap, client = fly()
    nan = math.nan
    assert client.command(mavlink2.MAV_CMD_NAV_TAKEOFF, nan, nan, nan, nan, nan, nan, nan) == (
        mavlink2.MAV_RESULT_DENIED
    ), "takeoff while disarmed"
    assert client.command(mavlink2.MAV_CMD_USER_1) == mavlink2.MAV_RESULT_UNSUPPORTED
    assert client.command(
        mavlink2.MAV_CMD_DO_SET_MODE, mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 3, 0
    ) == (mavlink2.MAV_RESULT_UNSUPPORTED), "POSCTL is not simulated"
    assert client.command(mavlink2.MAV_CMD_REQUEST_MESSAGE, 148) == mavlink2.MAV_RESULT_ACCEPTED
    version = client.recv("AUTOPILOT_VERSION")
    assert version.capabilities & mavlink2.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert client.command(mavlink2.MAV_CMD_REQUEST_MESSAGE, 12345) == (
        mavlink2.MAV_RESULT_UNSUPPORTED
    )
    assert client.command(mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1) == 0
    client.recv("AUTOPILOT_VERSION")
    # SET_MESSAGE_INTERVAL: 2 Hz of LOCAL_POSITION_NED is 500 ms of simulation time apart.
    assert client.command(mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, 32, 500_000) == 0
    client.clear("LOCAL_POSITION_NED")
    a = client.recv("LOCAL_POSITION_NED").time_boot_ms
    b = client.recv("LOCAL_POSITION_NED").time_boot_ms
    assert b - a == pytest.approx(500, abs=20)
    assert client.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
    client.recv("HEARTBEAT", lambda m: m.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
    assert ap.state.armed
    assert client.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 0) == 0
    assert not ap.state.armed


def test_param_and_mission_protocols_answer(fly) -> None:
    _runner, ap, client = fly()
    client.send(mavlink2.MAVLink_param_request_read_message(1, 1, b"MIS_TAKEOFF_ALT", -1))
    value = client.recv("PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    assert value.param_value == pytest.approx(TAKEOFF_ALT_M)
    client.send(
        mavlink2.MAVLink_param_set_message(
            1, 1, b"COM_OF_LOSS_T", 2.5, mavlink2.MAV_PARAM_TYPE_REAL32
        )
    )
    client.recv("PARAM_VALUE", lambda m: m.param_id == "COM_OF_LOSS_T" and m.param_value == 2.5)
    assert ap.param("COM_OF_LOSS_T") == 2.5
    # Integer parameters are encoded bytewise in the float, as PX4 does.
    client.send(mavlink2.MAVLink_param_request_read_message(1, 1, b"NAV_DLL_ACT", -1))
    dll = client.recv("PARAM_VALUE", lambda m: m.param_id == "NAV_DLL_ACT")
    assert dll.param_type == mavlink2.MAV_PARAM_TYPE_INT32
    assert struct.unpack("<i", struct.pack("<f", dll.param_value))[0] == 1  # hold
    client.send(
        mavlink2.MAVLink_param_set_message(
            1, 1, b"MIS_TAKEOFF_ALT", math.nan, mavlink2.MAV_PARAM_TYPE_REAL32
        )
    )
    client.recv("PARAM_VALUE", lambda m: m.param_id == "MIS_TAKEOFF_ALT")
    assert ap.param("MIS_TAKEOFF_ALT") == TAKEOFF_ALT_M
    wait_until(lambda: ap.rejected["bad_param_value"] == 1, 5.0, "bad param value counted")
    client.send(mavlink2.MAVLink_param_request_list_message(1, 1))
    first = client.recv("PARAM_VALUE")
    seen = {first.param_index}
    while len(seen) < first.param_count:
        seen.add(client.recv("PARAM_VALUE").param_index)
    client.send(mavlink2.MAVLink_mission_request_list_message(1, 1, 0))
    assert client.recv("MISSION_COUNT").count == 0
    client.send(mavlink2.MAVLink_mission_clear_all_message(1, 1, 0))
    assert client.recv("MISSION_ACK").type == mavlink2.MAV_MISSION_ACCEPTED


def test_gcs_link_streams_telemetry_and_accepts_commands(sim_runner) -> None:
    settings, _offboard_port, gcs_port = make_settings()
    runner = sim_runner([settings])
    gcs = Client(gcs_port, 1)
    try:
        gcs.connect()
        assert gcs.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
        assert runner.autopilots[0].state.armed
        gcs.recv("GLOBAL_POSITION_INT")
        assert runner.autopilots[0].offboard_address != runner.autopilots[0].gcs_address
    finally:
        gcs.close()


def test_handler_exception_is_counted_and_the_endpoint_keeps_working(
    fly, monkeypatch: pytest.MonkeyPatch
) -> None:
    def boom(self: ParamProtocol, *args: Any) -> None:
        raise RuntimeError("injected")

    monkeypatch.setattr(ParamProtocol, "on_request_list", boom)
    _runner, ap, client = fly()
    client.send(mavlink2.MAVLink_param_request_list_message(1, 1))
    wait_until(lambda: ap.rejected["handler_error"] == 1, 5.0, "handler error counted")
    assert client.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == 0
