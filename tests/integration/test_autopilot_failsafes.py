"""The simulated vehicle over real UDP MAVLink 2, driven by pymavlink clients: the PX4 offboard rules and failsafes, and
how setpoints are flown (type masks, speed and acceleration limits).

Each client listens as PX4's offboard client does (`udpin:127.0.0.1:PORT`, the vehicle sending to
PORT) and answers the vehicle from there (tests/support/autopilot_client.py). The simulation runs
at `SIM_SPEED` x real time in its own thread; tests wait for events with generous wall-clock
deadlines.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from sim.vehicle import VehicleLimits
from tests.support.autopilot_client import (
    HOLD,
    LAND,
    MASK_POSITION_ONLY,
    MASK_POSITION_YAW,
    MASK_VELOCITY_ONLY,
    OFFBOARD,
    TAKEOFF_ALT_M,
    enter_offboard,
    near,
    take_off,
)
from tests.support.sim_harness import wait_until

pytestmark = pytest.mark.timeout(90)


def test_offboard_is_refused_without_a_setpoint_stream(fly) -> None:
    runner, ap, client = fly()
    take_off(ap, client)
    assert client.set_mode(FlightMode.OFFBOARD) == mavlink2.MAV_RESULT_DENIED
    assert ap.state.mode is FlightMode.HOLD
    # One setpoint long ago is not a stream either.
    client.send(client.position_target(MASK_POSITION_YAW, (0.0, 0.0, -TAKEOFF_ALT_M)))
    t0 = runner.clock.now_s
    wait_until(lambda: runner.clock.now_s > t0 + 1.0, 10.0, "1 s of simulation time")
    assert client.set_mode(FlightMode.OFFBOARD) == mavlink2.MAV_RESULT_DENIED
    client.stream(MASK_POSITION_YAW, (0.0, 0.0, -TAKEOFF_ALT_M))
    wait_until(lambda: client.set_mode(FlightMode.OFFBOARD) == 0, 10.0, "OFFBOARD accepted")
    client.recv("HEARTBEAT", lambda m: m.custom_mode == OFFBOARD)
    assert ap.state.mode is FlightMode.OFFBOARD


def test_offboard_loss_falls_back_to_hold_after_com_of_loss_t(fly) -> None:
    runner, ap, client = fly(offboard_loss_timeout_s=1.0)
    take_off(ap, client)
    enter_offboard(ap, client, (10.0, 0.0, -TAKEOFF_ALT_M))
    wait_until(lambda: near(ap, (10.0, 0.0, -TAKEOFF_ALT_M), 0.5), 20.0, "at the setpoint")
    client.stop_stream()
    stopped_s = runner.clock.now_s
    client.recv("HEARTBEAT", lambda m: m.custom_mode == HOLD)
    # Not before COM_OF_LOSS_T of simulation time (minus one wall-clock stream period).
    assert ap.state.time_s >= stopped_s + 1.0 - 0.04 * runner.clock.speed
    assert ap.state.mode is FlightMode.HOLD and ap.state.armed and not ap.state.landed
    client.recv("STATUSTEXT", lambda m: "Offboard" in m.text)
    assert near(ap, (10.0, 0.0, -TAKEOFF_ALT_M), 0.5), "holds where it was"


@pytest.mark.parametrize(("action", "mode"), [("hold", HOLD), ("land", LAND)], ids=["hold", "land"])
def test_lost_gcs_takes_the_configured_action(fly, action: str, mode: int) -> None:
    runner, ap, client = fly(gcs_loss_timeout_s=3.0, gcs_loss_action=action)
    take_off(ap, client)
    enter_offboard(ap, client, (0.0, 0.0, -TAKEOFF_ALT_M))
    client.stream_heartbeats = False  # setpoints keep coming; heartbeats stop
    silent_s = runner.clock.now_s
    client.recv("HEARTBEAT", lambda m: m.custom_mode == mode, timeout_s=20.0)
    assert ap.state.time_s >= silent_s + 3.0 - 0.2 * runner.clock.speed
    assert ap.state.gcs_lost
    if action == "land":
        wait_until(lambda: ap.state.landed and not ap.state.armed, 30.0, "landed and disarmed")
    else:
        assert ap.state.mode is FlightMode.HOLD and not ap.state.landed
    client.stream_heartbeats = True
    wait_until(lambda: not ap.state.gcs_lost, 10.0, "link regained")


# -- setpoints --------------------------------------------------------------------------------


def test_type_mask_position_only_and_velocity_only(fly) -> None:
    _runner, ap, client = fly()
    take_off(ap, client)
    target = (20.0, -10.0, -8.0)
    enter_offboard(ap, client, (0.0, 0.0, -TAKEOFF_ALT_M))
    client.stream(MASK_POSITION_ONLY, target, (50.0, 50.0, 50.0))  # velocities must be ignored
    wait_until(lambda: near(ap, target, 0.2), 30.0, "position-only setpoint reached")
    # Velocity only; NaN in the ignored position fields must not matter.
    client.stream(MASK_VELOCITY_ONLY, (math.nan, math.nan, math.nan), (2.0, 1.0, 0.0))
    wait_until(
        lambda: np.allclose(ap.state.velocity_ned_mps, (2.0, 1.0, 0.0), atol=1e-3),
        20.0,
        "velocity-only setpoint tracked",
    )
    p0 = ap.state.position_ned_m.copy()
    t0 = ap.state.time_s
    wait_until(lambda: ap.state.time_s > t0 + 2.0, 10.0, "2 s of simulation time")
    moved = ap.state.position_ned_m - p0
    dt = ap.state.time_s - t0
    assert moved[:2] == pytest.approx((2.0 * dt, 1.0 * dt), rel=0.05)
    assert abs(moved[2]) < 0.05
    assert not ap.rejected


def test_horizontal_speed_and_acceleration_limits_hold(fly) -> None:
    limits = VehicleLimits(max_horizontal_speed_mps=6.0, max_horizontal_accel_mps2=2.0)
    _runner, ap, client = fly(limits=limits)
    take_off(ap, client)
    enter_offboard(ap, client, (0.0, 0.0, -TAKEOFF_ALT_M))
    samples: list[tuple[float, float, float]] = []

    def sample() -> bool:
        m = client.recv("LOCAL_POSITION_NED")
        samples.append((m.time_boot_ms * 1e-3, m.vx, m.vy))
        return near(ap, (40.0, 30.0, -TAKEOFF_ALT_M), 0.3)

    client.stream(MASK_POSITION_YAW, (40.0, 30.0, -TAKEOFF_ALT_M))
    wait_until(sample, 40.0, "arrival 50 m away", poll_s=0.0)
    t, vx, vy = (np.array(c) for c in zip(*samples, strict=True))
    speed = np.hypot(vx, vy)
    dt = np.diff(t)
    ok = dt > 0
    accel = np.hypot(np.diff(vx)[ok], np.diff(vy)[ok]) / dt[ok]
    # float32 velocities: 1e-3 relative margin covers the rounding.
    assert speed.max() <= 6.0 * (1 + 1e-3)
    assert speed.max() >= 6.0 * 0.99, "the speed limit is reached on a 50 m leg"
    assert accel.max() <= 2.0 * (1 + 1e-3)
    assert accel.max() >= 2.0 * 0.9, "the acceleration limit is reached"
