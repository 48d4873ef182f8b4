"""The simulated vehicle over real UDP MAVLink 2, driven by pymavlink clients.

Each client listens as PX4's offboard client does (`udpin:127.0.0.1:PORT`, the vehicle sending to
PORT) and answers the vehicle from there. The simulation runs at `SIM_SPEED` x real time in its
own thread; tests wait for events by polling with generous wall-clock deadlines.
"""

from __future__ import annotations

import math
import os
import socket
import struct
import threading
import time
from collections import defaultdict, deque
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from isac_mission.frames import scenario_to_geodetic
from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.params import ParamProtocol
from sim.autopilot.settings import AutopilotSettings
from sim.vehicle import VehicleLimits
from tests.support.sim_harness import SimRunner, free_udp_ports, wait_until

pytestmark = pytest.mark.timeout(90)

TAKEOFF_ALT_M = 5.0
MASK_POSITION_YAW = 0x9F8  # MAVSDK's position + yaw setpoint
MASK_POSITION_ONLY = 0xDF8  # x, y, z used; velocity, acceleration, yaw, yaw rate ignored
MASK_VELOCITY_ONLY = 0xDC7  # vx, vy, vz used; position, acceleration, yaw, yaw rate ignored
HOLD = FlightMode.HOLD.px4_custom_mode
OFFBOARD = FlightMode.OFFBOARD.px4_custom_mode
LAND = FlightMode.LAND.px4_custom_mode


class Client:
    """A pymavlink offboard client: `udpin` on the port the vehicle sends to.

    A receiver thread drains the socket all the time (the vehicle sends a few hundred messages
    per wall second at speed 4, which would overflow an unread socket buffer and drop the very
    COMMAND_ACK a test waits for) and queues messages by type; `recv` consumes those queues.
    """

    def __init__(self, port: int, target_system: int) -> None:
        self.conn: Any = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190, dialect="common"
        )
        self.target = target_system
        self._lock = threading.Lock()
        self._queues: dict[str, deque[Any]] = defaultdict(lambda: deque(maxlen=5000))
        self._cond = threading.Condition()
        self._closed = threading.Event()
        self._rx = threading.Thread(target=self._rx_loop, daemon=True)
        self._rx.start()
        self.setpoint: tuple[int, tuple[float, ...]] | None = None
        self.stream_heartbeats = True
        self._tx = threading.Thread(target=self._tx_loop, daemon=True)

    def _rx_loop(self) -> None:
        while not self._closed.is_set():
            msg = self.conn.recv_match(blocking=True, timeout=0.1)
            if msg is not None:
                with self._cond:
                    self._queues[msg.get_type()].append(msg)
                    self._cond.notify_all()

    def send(self, msg: Any) -> None:
        with self._lock:
            self.conn.mav.send(msg)

    def clear(self, mtype: str) -> None:
        """Forget the queued messages of `mtype` (so `recv` sees only newer ones)."""
        with self._cond:
            self._queues[mtype].clear()

    def recv(
        self, mtype: str, condition: Callable[[Any], bool] = lambda m: True, timeout_s: float = 15.0
    ) -> Any:
        """The next queued message of `mtype` satisfying `condition` (AssertionError on timeout)."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                queue = self._queues[mtype]
                while queue:
                    msg = queue.popleft()
                    if condition(msg):
                        return msg
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise AssertionError(f"no {mtype} matching the condition within {timeout_s} s")
                self._cond.wait(remaining)

    def connect(self) -> Any:
        """Wait for the vehicle's heartbeat (after which the client can send) and answer it."""
        hb = self.recv("HEARTBEAT", lambda m: m.get_srcSystem() == self.target)
        self.heartbeat()
        self._tx.start()
        return hb

    def heartbeat(self) -> None:
        self.send(
            mavlink2.MAVLink_heartbeat_message(
                mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3
            )
        )

    def command(self, command: int, *params: float, timeout_s: float = 10.0) -> int:
        """Send COMMAND_LONG and return the result of its COMMAND_ACK."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.clear("COMMAND_ACK")
        self.send(
            mavlink2.MAVLink_command_long_message(self.target, 1, command, 0, *p)  # type: ignore[arg-type]
        )
        ack = self.recv("COMMAND_ACK", lambda m: m.command == command, timeout_s)
        return int(ack.result)

    def set_mode(self, mode: FlightMode) -> int:
        custom = mode.px4_custom_mode
        return self.command(
            mavlink2.MAV_CMD_DO_SET_MODE,
            mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            (custom >> 16) & 0xFF,
            (custom >> 24) & 0xFF,
        )

    def position_target(
        self,
        mask: int,
        xyz: tuple[float, float, float] = (0.0, 0.0, 0.0),
        vxyz: tuple[float, float, float] = (0.0, 0.0, 0.0),
        yaw: float = 0.0,
        target_system: int | None = None,
    ) -> Any:
        return mavlink2.MAVLink_set_position_target_local_ned_message(
            0,
            self.target if target_system is None else target_system,
            1,
            mavlink2.MAV_FRAME_LOCAL_NED,
            mask,
            *xyz,
            *vxyz,
            0.0,
            0.0,
            0.0,
            yaw,
            0.0,
        )

    def stream(
        self,
        mask: int,
        xyz: tuple[float, float, float],
        vxyz: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        """Stream this setpoint at 25 Hz wall from now on (replacing the previous one)."""
        self.setpoint = (mask, (*xyz, *vxyz))

    def stop_stream(self) -> None:
        """Stop sending setpoints (heartbeats go on)."""
        self.setpoint = None

    def _tx_loop(self) -> None:
        """Setpoints at 25 Hz and heartbeats at 5 Hz of wall time (above 1 Hz of simulation
        time at speed 4, so a lost-GCS timeout of a few simulated seconds never fires by chance)."""
        k = 0
        while not self._closed.wait(0.04):
            setpoint = self.setpoint
            if setpoint is not None:
                mask, v = setpoint
                self.send(self.position_target(mask, v[:3], v[3:]))  # type: ignore[arg-type]
            if self.stream_heartbeats and k % 5 == 0:
                self.heartbeat()
            k += 1

    def close(self) -> None:
        self._closed.set()
        self._rx.join(timeout=5.0)
        if self._tx.is_alive():
            self._tx.join(timeout=5.0)
        self.conn.close()


def make_settings(index: int = 0, **overrides: Any) -> tuple[AutopilotSettings, int, int]:
    offboard_port, gcs_port = free_udp_ports(2)
    settings = AutopilotSettings(
        index=index,
        offboard_port=offboard_port,
        gcs_port=gcs_port,
        takeoff_alt_m=TAKEOFF_ALT_M,
        **overrides,
    )
    return settings, offboard_port, gcs_port


@pytest.fixture
def fly(sim_runner) -> Iterator[Callable[..., tuple[SimRunner, Autopilot, Client]]]:
    """Factory: one vehicle with `overrides`, a connected client; closed at teardown."""
    clients: list[Client] = []

    def make(**overrides: Any) -> tuple[SimRunner, Autopilot, Client]:
        settings, port, _ = make_settings(**overrides)
        runner = sim_runner([settings])
        client = Client(port, settings.system_id)
        clients.append(client)
        client.connect()
        return runner, runner.autopilots[0], client

    yield make
    for client in clients:
        client.close()


def take_off(ap: Autopilot, client: Client) -> None:
    assert client.command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink2.MAV_RESULT_ACCEPTED
    nan = math.nan
    assert (
        client.command(mavlink2.MAV_CMD_NAV_TAKEOFF, nan, nan, nan, nan, nan, nan, nan)
        == mavlink2.MAV_RESULT_ACCEPTED
    )
    wait_until(
        lambda: ap.state.mode is FlightMode.HOLD and not ap.state.landed, 20.0, "takeoff complete"
    )
    assert ap.state.altitude_m == pytest.approx(TAKEOFF_ALT_M, abs=0.25)


def enter_offboard(ap: Autopilot, client: Client, xyz: tuple[float, float, float]) -> None:
    client.stream(MASK_POSITION_YAW, xyz)
    wait_until(lambda: client.set_mode(FlightMode.OFFBOARD) == 0, 10.0, "OFFBOARD accepted")
    client.recv("HEARTBEAT", lambda m: m.custom_mode == OFFBOARD)


def near(ap: Autopilot, ned: tuple[float, float, float], tol_m: float) -> bool:
    return math.dist(tuple(ap.state.position_ned_m), ned) < tol_m


# -- identity, telemetry, protocols -----------------------------------------------------------


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


# -- offboard rules and failsafes --------------------------------------------------------------


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


# -- bad input --------------------------------------------------------------------------------


def raw_send(ap: Autopilot, data: bytes) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        s.sendto(data, ap.offboard_address)


def mavlink2_frame(msg_id: int, payload: bytes, sysid: int = 255, seq: int = 0) -> bytes:
    """A MAVLink 2 frame with any message id (CRC without crc_extra: unknown ids have none)."""
    header = struct.pack(
        "<BBBBBBBHB", 0xFD, len(payload), 0, 0, seq, sysid, 190, msg_id & 0xFFFF, msg_id >> 16
    )
    crc = mavlink2.x25crc(header[1:] + payload).crc
    return header + payload + struct.pack("<H", crc)


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
