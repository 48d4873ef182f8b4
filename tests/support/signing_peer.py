"""Helpers of the MAVLink 2 signing tests (tests/integration/test_signing_*.py): the keys, a
stock pymavlink peer on its own 127.0.0.1 socket (the operator, an attacker or a fake vehicle;
the operator's signing set up as `mavutil.setup_signing` does), a signed simulated vehicle, and
the scenarios and bridges of the end-to-end tests.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from isac_mission.bus import ZenohBus
from isac_mission.config import (
    MavlinkSigningKey,
    Scenario,
    parse_scenario,
)
from isac_mission.mavwire.builders import Target
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.signing import signing_timestamp
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.vehicle import VehicleBridge
from isac_mission.timebase import WallTime
from isac_mission.wire import Keys
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from tests.support.ports import free_udp_ports
from tests.support.sim_harness import SimRunner

ROOT = Path(__file__).resolve().parents[2]
HEX_KEY = "5a" * 16 + "c3" * 16
KEY = MavlinkSigningKey(bytes.fromhex(HEX_KEY), link_id=1, source="test")
WRONG_KEY = MavlinkSigningKey(bytes.fromhex("a5" * 32), link_id=1, source="test (wrong)")
SIGNING_REASONS = ("unsigned", "bad_signature", "replayed")
TIMEOUT_S = 30.0  # wall seconds for any single awaited event
SPEED = 10.0  # simulation seconds per wall second in the bridge tests
ALTITUDE_M = 10.0
VEHICLE = Target(1)
KEYS = Keys("signing-test")


class Peer:
    """A MAVLink peer on its own 127.0.0.1 UDP socket, speaking stock pymavlink.

    With a key it signs what it sends and checks what it receives, set up as
    `mavutil.setup_signing` does (wall-clock initial timestamp, no unsigned callback, so
    unsigned input is refused); without one it neither signs nor checks.
    """

    def __init__(
        self,
        dest: tuple[str, int],
        key: MavlinkSigningKey | None = None,
        system: int = 255,
        component: int = 190,
    ) -> None:
        self.dest = dest
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.mav = mavlink2.MAVLink(None, srcSystem=system, srcComponent=component)
        self.mav.robust_parsing = True
        if key is not None:
            self.mav.signing.secret_key = key.secret
            self.mav.signing.link_id = key.link_id
            self.mav.signing.sign_outgoing = True
            self.mav.signing.timestamp = signing_timestamp()
        self.heard: list[Any] = []
        """Every message received (good or BAD_DATA), in order."""

    def pack(self, msg: Any) -> bytes:
        data = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        return data

    def send(self, msg: Any) -> bytes:
        """Send `msg`; returns its wire bytes (to replay them)."""
        data = self.pack(msg)
        self.sock.sendto(data, self.dest)
        return data

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.dest)

    def recv_until(self, condition: Callable[[Any], bool], timeout_s: float) -> Any | None:
        """The first message received within `timeout_s` wall seconds satisfying `condition`."""
        deadline = time.monotonic() + timeout_s
        while (remaining := deadline - time.monotonic()) > 0:
            self.sock.settimeout(remaining)
            try:
                data, _ = self.sock.recvfrom(65535)
            except TimeoutError:
                return None
            for msg in self.mav.parse_buffer(data) or []:
                self.heard.append(msg)
                if condition(msg):
                    return msg
        return None

    def drain(self) -> list[Any]:
        """Everything waiting in the socket now (non-blocking), also appended to `heard`."""
        out: list[Any] = []
        self.sock.setblocking(False)
        try:
            while True:
                data, _ = self.sock.recvfrom(65535)
                out.extend(self.mav.parse_buffer(data) or [])
        except BlockingIOError:
            pass
        finally:
            self.sock.setblocking(True)
        self.heard.extend(out)
        return out

    def command(self, msg: Any, timeout_s: float = TIMEOUT_S) -> tuple[int, bytes]:
        """Send a COMMAND_LONG; (result of its COMMAND_ACK, the command's wire bytes)."""
        data = self.send(msg)
        ack = self.recv_until(
            lambda m: m.get_type() == "COMMAND_ACK" and m.command == msg.command, timeout_s
        )
        assert ack is not None, f"no COMMAND_ACK for {msg.command} within {timeout_s} s"
        return int(ack.result), data

    def close(self) -> None:
        self.sock.close()


def signed_vehicle(
    sim_runner: Callable[..., SimRunner], key: MavlinkSigningKey | None
) -> Autopilot:
    """One simulated vehicle (system 1) with signing `key`, its telemetry sent to free ports."""
    offboard_port, gcs_port = free_udp_ports(2)
    settings = AutopilotSettings(
        index=0,
        offboard_port=offboard_port,
        gcs_port=gcs_port,
        bind_port=0,
        gcs_bind_port=0,
        takeoff_alt_m=5.0,
        signing=key,
    )
    return sim_runner([settings]).autopilots[0]


def one_uav_scenario(**security: Any) -> Scenario:
    """A valid one-UAV scenario with these security.mavlink_signing fields."""
    return parse_scenario(
        {
            "uavs": {"start_xy_m": [[1500.0, 1500.0]]},
            "security": {"mavlink_signing": security},
        }
    )


def vehicle_heartbeat(armed: bool = False) -> Any:
    base = mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if armed:
        base |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
    return mavlink2.MAVLink_heartbeat_message(
        mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_PX4, base, 0x03040000, 4, 3
    )


def local_position(north_m: float) -> Any:
    return mavlink2.MAVLink_local_position_ned_message(1000, north_m, 0.0, -5.0, 0.0, 0.0, 0.0)


def bridge_for(
    ap: Autopilot, hub: ZenohBus, key: MavlinkSigningKey | None, **overrides: Any
) -> VehicleBridge:
    """A bridge on the port vehicle `ap` sends to (WallTime: these runs fail before flying)."""
    port = ap.settings.offboard_dest_port
    settings = BridgeSettings(index=0, port=port, signing=key, **overrides)
    return VehicleBridge(settings, WallTime(), KEYS, hub)


def write_signing_scenario(tmp_path: Path, name: str, signing: dict[str, Any]) -> Path:
    """config/paper.yaml with a security.mavlink_signing section, written to tmp_path."""
    data = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    data["security"] = {"mavlink_signing": signing}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path
