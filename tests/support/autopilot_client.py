"""A pymavlink offboard client of the simulated vehicle, and the helpers of its integration tests
(tests/integration/test_autopilot_*.py).

The client listens as PX4's offboard client does (`udpin:127.0.0.1:PORT`, the vehicle sending to
PORT) and answers the vehicle from there. The simulation runs at `SIM_SPEED` x real time in its
own thread; the helpers wait for events with generous wall-clock deadlines.
"""

from __future__ import annotations

import math
import os
import socket
import struct
import threading
import time
from collections import defaultdict, deque
from collections.abc import Callable
from typing import Any

import pytest

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink2

from isac_mission.mavwire.modes import FlightMode
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from tests.support.ports import free_udp_ports
from tests.support.sim_harness import wait_until

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
        **({"bind_port": 0, "gcs_bind_port": 0} | overrides),
    )
    return settings, offboard_port, gcs_port


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
