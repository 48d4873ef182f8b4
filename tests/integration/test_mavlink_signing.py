"""MAVLink 2 signing over real loopback UDP: simulated vehicles and the service's bridges obey
and believe only correctly signed messages, and count what they drop.

Peers that play the operator, the attacker or a fake vehicle are stock pymavlink `MAVLink`
objects on their own 127.0.0.1 sockets (the operator's signing set up as
`mavutil.setup_signing` does), so the tests also check that our signatures interoperate with
pymavlink's. Tests wait for events (counters, states, messages) with generous wall-clock
deadlines; nothing sleeps to synchronise.
"""

from __future__ import annotations

import asyncio
import logging
import math
import os
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.config import (
    DEFAULT_SIGNING_KEY_ENV,
    MavlinkSigningKey,
    Scenario,
    load_scenario,
    parse_scenario,
)
from isac_mission.errors import LinkError
from isac_mission.mavwire.builders import Target, arm_command, takeoff_command
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.modes import FlightMode
from isac_mission.mavwire.signing import signing_timestamp
from isac_mission.service.bridge.clock_time import ClockSimTime
from isac_mission.service.bridge.fleet import BridgeFleet
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.vehicle import VehicleBridge
from isac_mission.timebase import WallTime
from isac_mission.wire import Keys
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from sim.world import World
from sim.world_options import WorldOptions
from tests.support.ports import free_port_block
from tests.support.sim_harness import SimRunner, async_wait_until, free_udp_ports, wait_until

pytestmark = pytest.mark.timeout(150)

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


# --------------------------------------------------------------------------- a pymavlink peer


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


@pytest.fixture
def peers() -> Any:
    """Factory `peers(dest, key)`: Peers closed at teardown."""
    made: list[Peer] = []

    def make(dest: tuple[str, int], key: MavlinkSigningKey | None = None, **kw: Any) -> Peer:
        peer = Peer(dest, key, **kw)
        made.append(peer)
        return peer

    yield make
    for peer in made:
        peer.close()


def signed_vehicle(
    sim_runner: Callable[..., SimRunner], key: MavlinkSigningKey | None
) -> Autopilot:
    """One simulated vehicle (system 1) with signing `key`, its telemetry sent to free ports."""
    offboard_port, gcs_port = free_udp_ports(2)
    settings = AutopilotSettings(
        index=0, offboard_port=offboard_port, gcs_port=gcs_port, takeoff_alt_m=5.0, signing=key
    )
    return sim_runner([settings]).autopilots[0]


# --------------------------------------------------------------------------- 1. the vehicle


def test_vehicle_obeys_only_correctly_signed_commands(
    sim_runner: Callable[..., SimRunner], peers: Any
) -> None:
    ap = signed_vehicle(sim_runner, KEY)
    dest = ap.offboard_address
    unsigned = peers(dest)
    forger = peers(dest, WRONG_KEY)
    operator = peers(dest, KEY)

    unsigned.send(arm_command(VEHICLE))
    wait_until(lambda: ap.rejected["unsigned"] == 1, TIMEOUT_S, "unsigned ARM counted")
    forger.send(arm_command(VEHICLE))
    wait_until(lambda: ap.rejected["bad_signature"] == 1, TIMEOUT_S, "wrongly signed ARM counted")
    # A forged packet with a far-future timestamp must not lock the operator's stream out.
    forger.mav.signing.timestamp = 2**47
    forger.send(arm_command(VEHICLE))
    wait_until(lambda: ap.rejected["bad_signature"] == 2, TIMEOUT_S, "future-dated forgery counted")
    assert not ap.armed and ap.landed

    result, arm_bytes = operator.command(arm_command(VEHICLE))
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    assert ap.armed
    result, _ = operator.command(arm_command(VEHICLE, arm=False))
    assert result == mavlink2.MAV_RESULT_ACCEPTED
    assert not ap.armed
    # The operator's ARM replayed verbatim (from another socket) is refused.
    unsigned.send_raw(arm_bytes)
    wait_until(lambda: ap.rejected["replayed"] == 1, TIMEOUT_S, "replayed ARM counted")
    assert not ap.armed

    assert operator.command(arm_command(VEHICLE))[0] == mavlink2.MAV_RESULT_ACCEPTED
    assert operator.command(takeoff_command(VEHICLE))[0] == mavlink2.MAV_RESULT_ACCEPTED
    wait_until(
        lambda: ap.state.mode is FlightMode.HOLD and not ap.state.landed, TIMEOUT_S, "takeoff"
    )
    assert {r: ap.rejected[r] for r in SIGNING_REASONS} == {
        "unsigned": 1,
        "bad_signature": 2,
        "replayed": 1,
    }
    # Whoever failed the check got nothing back: no ACK, and not even telemetry (a rejected
    # sender does not become a peer of the link). The operator's telemetry is signed with KEY.
    assert unsigned.drain() == [] and unsigned.heard == []
    assert forger.drain() == [] and forger.heard == []
    telemetry = operator.recv_until(lambda m: m.get_type() == "LOCAL_POSITION_NED", TIMEOUT_S)
    assert telemetry is not None and telemetry.get_signed()
    assert not [m for m in operator.heard if m.get_type() == "BAD_DATA"]
    assert ap.signatures_ok >= 4


def test_vehicle_without_signing_accepts_unsigned_commands(
    sim_runner: Callable[..., SimRunner], peers: Any
) -> None:
    """Signing off (the default) behaves as before: unsigned commands are obeyed."""
    ap = signed_vehicle(sim_runner, None)
    client = peers(ap.offboard_address)
    assert client.command(arm_command(VEHICLE))[0] == mavlink2.MAV_RESULT_ACCEPTED
    assert ap.armed
    hb = client.recv_until(lambda m: m.get_type() == "HEARTBEAT", TIMEOUT_S)
    assert hb is not None and not hb.get_header().incompat_flags & 1
    assert not ap.rejected and ap.signatures_ok == 0


# --------------------------------------------------------------------------- 2. the bridge


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


async def test_bridge_believes_only_correctly_signed_telemetry(
    hub: ZenohBus, peers: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(DEFAULT_SIGNING_KEY_ENV, HEX_KEY)
    scenario = one_uav_scenario(enabled=True, link_id=2)
    base_port = free_port_block(1)
    fleet = BridgeFleet.from_scenario(scenario, WallTime(), hub, base_port=base_port)
    async with fleet:
        link = fleet.bridges[0].link
        dest = ("127.0.0.1", base_port)
        unsigned = peers(dest, system=1, component=1)
        forger = peers(dest, WRONG_KEY, system=1, component=1)
        vehicle = peers(dest, KEY, system=1, component=1)

        for fake in (unsigned, forger):
            fake.send(vehicle_heartbeat(armed=True))
            fake.send(local_position(100.0))
        await async_wait_until(
            lambda: link.errors["unsigned"] == 2 and link.errors["bad_signature"] == 2,
            TIMEOUT_S,
            f"forged telemetry counted (so far {dict(link.errors)})",
        )
        st = link.status()
        # Nothing forged was believed: no vehicle, no address to send commands to.
        assert st.heartbeat_s is None and st.lost and not st.armed
        assert st.position_ned_m is None and st.address is None
        assert not link.received

        vehicle.send(vehicle_heartbeat())
        position_bytes = vehicle.send(local_position(7.0))
        st = await link.wait_for(
            lambda s: s.position_ned_m is not None, TIMEOUT_S, "signed telemetry"
        )
        assert not st.lost and st.mode == "hold" and not st.armed
        assert st.position_ned_m is not None and st.position_ned_m[0] == 7.0
        # The bridge answers the signed vehicle with signed GCS heartbeats.
        hb = await asyncio.to_thread(
            vehicle.recv_until, lambda m: m.get_type() == "HEARTBEAT", TIMEOUT_S
        )
        assert hb is not None and hb.get_signed() and hb.get_srcSystem() == 255
        assert hb.get_header().incompat_flags & 1
        assert not [m for m in vehicle.heard if m.get_type() == "BAD_DATA"]

        # Replayed and forged updates after the genuine one change nothing.
        vehicle.send_raw(position_bytes)
        forger.send(vehicle_heartbeat(armed=True))
        await async_wait_until(
            lambda: link.errors["replayed"] == 1 and link.errors["bad_signature"] == 3,
            TIMEOUT_S,
            f"replay and forgery counted (so far {dict(link.errors)})",
        )
        assert not link.status().armed
        assert {r: link.errors[r] for r in SIGNING_REASONS} == {
            "unsigned": 2,
            "bad_signature": 3,
            "replayed": 1,
        }
        assert link.signatures_ok == 2
        assert unsigned.drain() == [] and forger.drain() == []


# --------------------------------------------------------------------------- 3. end to end


def bridge_for(
    ap: Autopilot, hub: ZenohBus, key: MavlinkSigningKey | None, **overrides: Any
) -> VehicleBridge:
    """A bridge on the port vehicle `ap` sends to (WallTime: these runs fail before flying)."""
    port = ap.settings.offboard_dest_port
    settings = BridgeSettings(index=0, port=port, signing=key, **overrides)
    return VehicleBridge(settings, WallTime(), KEYS, hub)


@pytest.mark.parametrize(
    ("bridge_key", "reason"),
    [(None, "unsigned"), (WRONG_KEY, "bad_signature")],
    ids=["unsigned-bridge", "wrong-key-bridge"],
)
async def test_a_bridge_without_the_key_cannot_fly_a_signed_vehicle(
    sim_runner: Callable[..., SimRunner],
    hub: ZenohBus,
    bridge_key: MavlinkSigningKey | None,
    reason: str,
) -> None:
    ap = signed_vehicle(sim_runner, KEY)
    bridge = bridge_for(ap, hub, bridge_key, connect_timeout_s=3.0, command_attempts=2)
    async with bridge:
        with pytest.raises(LinkError):
            await asyncio.wait_for(bridge.prepare((0.0, 10.0), ALTITUDE_M), TIMEOUT_S)
        if bridge_key is None:
            # The bridge cannot check signatures, so it hears the vehicle and sends it unsigned
            # heartbeats and its ARM command: the vehicle refuses and counts them all.
            assert ap.rejected["unsigned"] >= 3
            assert bridge.link.errors["unsigned"] == 0
        else:
            # The vehicle's telemetry fails the bridge's check: the bridge never even learns
            # where the vehicle is, so it sends nothing.
            assert bridge.link.errors["bad_signature"] >= 3
            assert bridge.link.status().address is None
            assert ap.rejected[reason] == 0
    assert not ap.armed and ap.landed


def write_signing_scenario(tmp_path: Path, name: str, signing: dict[str, Any]) -> Path:
    """config/paper.yaml with a security.mavlink_signing section, written to tmp_path."""
    data = yaml.safe_load((ROOT / "config" / "paper.yaml").read_text())
    data["security"] = {"mavlink_signing": signing}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


async def test_signed_fleet_of_the_world_takes_off_follows_setpoints_and_lands(
    hub: ZenohBus,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO)
    # The vehicles read the key from a file, the service from an environment variable.
    key_file = tmp_path / "mavlink.key"
    key_file.write_text(HEX_KEY + "\n")
    monkeypatch.setenv("FLEET_KEY", HEX_KEY)
    world_cfg = load_scenario(
        write_signing_scenario(tmp_path, "w.yaml", {"enabled": True, "key_file": str(key_file)})
    )
    service_cfg = load_scenario(
        write_signing_scenario(tmp_path, "s.yaml", {"enabled": True, "key_env": "FLEET_KEY"})
    )
    world_key, service_key = world_cfg.mavlink_signing_key, service_cfg.mavlink_signing_key
    assert world_key is not None and service_key is not None
    assert world_key.source != service_key.source and world_key.secret == service_key.secret

    def flying(s: Scenario) -> Scenario:
        return s.with_changes(H=ALTITUDE_M, dt=2.0, mission_id=KEYS.mission)

    world_cfg, service_cfg = flying(world_cfg), flying(service_cfg)
    n = world_cfg.M
    options = WorldOptions(
        speed=SPEED,
        bus=BusSettings(connect=(hub.settings.listen[0],)),
        mavlink_base_port=free_port_block(n),
        gcs_base_port=free_port_block(n),
        start="offboard",
    )
    world = World(world_cfg, options)
    stop = asyncio.Event()
    world_task: asyncio.Task[None] | None = None
    fleet = BridgeFleet.from_scenario(
        service_cfg, ClockSimTime(), hub, base_port=options.mavlink_base_port
    )
    try:
        await world.open()
        world_task = asyncio.create_task(world.run(stop))
        async with fleet:
            await asyncio.wait_for(fleet.prepare_all(), 2 * TIMEOUT_S)
            for v in world.vehicles:
                assert v.armed and v.state.mode is FlightMode.OFFBOARD
                assert abs(v.state.altitude_m - ALTITUDE_M) <= 1.0
            goals = world_cfg.uav_start_xy + np.array([6.0, -4.0])
            for bridge, goal in zip(fleet.bridges, goals, strict=True):
                bridge.set_waypoint(goal, None)
            await async_wait_until(
                lambda: all(
                    math.dist(v.state.position_xy_m, g) <= 1.0
                    for v, g in zip(world.vehicles, goals, strict=True)
                ),
                TIMEOUT_S,
                "every vehicle at its offboard setpoint",
            )
            await asyncio.wait_for(fleet.land_all(), 2 * TIMEOUT_S)
            for v in world.vehicles:
                assert v.state.landed and not v.armed
                # Everything the vehicle obeyed was signed; nothing failed the check.
                assert v.signatures_ok > 0
                assert not any(v.rejected[r] for r in SIGNING_REASONS)
            for bridge in fleet.bridges:
                assert bridge.link.signatures_ok > 0
                assert not any(bridge.link.errors[r] for r in SIGNING_REASONS)
    finally:
        stop.set()
        if world_task is not None:
            await asyncio.wait_for(world_task, TIMEOUT_S)
        await world.close()
    # The logs say signing is on and with which key (by fingerprint), never the key itself.
    assert f"MAVLink signing on (key {KEY.fingerprint}" in caplog.text
    assert HEX_KEY not in caplog.text.lower()
    assert KEY.secret.hex() not in caplog.text and repr(KEY.secret) not in caplog.text
