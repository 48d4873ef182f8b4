"""PX4-like autopilot for one simulated multirotor, with its MAVLink 2 endpoint (pymavlink).

One `Autopilot` is one vehicle: the flight-mode logic of a PX4 multirotor around the kinematic
core in `sim/vehicle.py`, and two UDP MAVLink links on 127.0.0.1 as PX4 SITL has them:

- the offboard link binds `bind_port` (default ephemeral) and sends to `offboard_port` (default
  14540 + index) where the offboard client listens (`udpin://127.0.0.1:14540` for MAVSDK);
- the GCS link binds `gcs_bind_port` (default ephemeral) and sends to `gcs_port` (default
  14550 + index) for a ground station.

Both links stream telemetry, accept every command, and also answer whoever speaks to them (the
sender's address joins the link's peers). Vehicle index m is MAVLink system m + 1, component 1.

Modes (PX4 custom modes in the heartbeat): HOLD (AUTO.LOITER), TAKEOFF (AUTO.TAKEOFF), LAND
(AUTO.LAND) and OFFBOARD; `armed` and `landed` complete the state (landed/disarmed, armed on the
ground, in the air). The PX4 rules that a ground service must respect are kept:

- OFFBOARD is DENIED unless SET_POSITION_TARGET_LOCAL_NED setpoints are streaming (the last one
  younger than 1 / `offboard_min_rate_hz`, 0.5 s); when they stop for COM_OF_LOSS_T the vehicle
  takes the offboard-loss action (HOLD or LAND) and says so in its heartbeat and a STATUSTEXT;
- after a client HEARTBEAT has been heard, silence on both links for COM_DL_LOSS_T makes an
  airborne vehicle take the datalink-loss action (NAV_DLL_ACT: none, HOLD or LAND);
- the vehicle disarms COM_DISARM_LAND after touching down and COM_DISARM_PRFLT after arming
  without taking off.

Time: everything runs on simulation time. The world's clock calls `step(now_s, dt_s)` at the
physics rate; `step` integrates the vehicle, checks the timeouts against `now_s` and sends the
telemetry that is due. Incoming messages are stamped with the latest `now_s`. A setpoint stream
therefore has to be faster than `offboard_min_rate_hz` in simulation time (at speed s: s times
that in wall time). Only a keep-alive heartbeat (`heartbeat_keepalive_wall_s`) runs on the wall
clock, so links stay up while the clock is held or slow.

Bad input is counted per reason in `rejected` (and logged): garbage bytes, bad CRC, unknown
message ids, truncated packets, non-finite or unsupported setpoints (dropped), setpoints out of
the area or below the minimum altitude (clamped), bad parameter values, commands with a NaN,
infinite or absurd integer parameter (answered DENIED), and handler exceptions.
Benign drops (messages for another system or component, message types this vehicle does not
handle) are counted in `ignored`. Nothing a client sends stops the vehicle from flying.

MAVLink 2 signing (`AutopilotSettings.signing`, a key): both links sign everything they send and
drop every packet without a valid signature, counted in `rejected` as `unsigned`,
`bad_signature` or `replayed` (see isac_mission/mavwire/signing.py); the vehicle neither obeys
nor answers such a packet, and its sender does not become a peer. Off by default, as in PX4 SITL.

Frames: local NED (north, east, down) around the scenario-plane point `local_origin_xy_m` on the
ground (scenario plane: x east, y north, so north = y - y0, east = x - x0, down = -altitude).
`geo_origin` is the geodetic position of the scenario origin (0, 0) on the ground; GPS positions
come from it by a flat-earth (equirectangular) conversion, so all vehicles of a scenario agree on
global positions whatever their local origins.

Threading: `open`, `close` and `step` must run on the event loop that owns the sockets.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import logging
import math
import struct
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import Any, Literal, cast

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from isac_mission.config import MavlinkSigningKey
from isac_mission.errors import ConfigError
from isac_mission.mavwire.parsing import packet_origin
from isac_mission.mavwire.signing import (
    enable_signing,
    new_encoder,
    new_parser,
    pack,
    refresh_signing_clock,
    signature_failure,
)
from isac_mission.types import FloatArray
from sim.vehicle import Setpoint, VehicleLimits, VehicleState, stopping_point, wrap_pi
from sim.vehicle import step as vehicle_step

logger = logging.getLogger(__name__)

LOOPBACK = "127.0.0.1"
EARTH_RADIUS_M = 6_378_137.0
GRAVITY_MPS2 = 9.80665
COMPONENT_ID = 1
OFFBOARD_BASE_PORT = 14540
GCS_BASE_PORT = 14550

_MAX_PEERS = 8
_LANDED_ALT_M = 0.05
_AIRBORNE_ALT_M = 0.1
_TAKEOFF_DONE_M = 0.2
_FORCE_DISARM_MAGIC = 21196.0

Address = tuple[str, int]

_RESULT_ACCEPTED: int = mavlink2.MAV_RESULT_ACCEPTED
_RESULT_DENIED: int = mavlink2.MAV_RESULT_DENIED
_RESULT_UNSUPPORTED: int = mavlink2.MAV_RESULT_UNSUPPORTED
_INTEGER_PARAMS: dict[int, int] = {
    mavlink2.MAV_CMD_DO_SET_MODE: 3,
    mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL: 1,
    mavlink2.MAV_CMD_REQUEST_MESSAGE: 1,
}
"""Commands whose first n parameters are integers carried in floats (a mode, a message id)."""
LossAction = Literal["none", "hold", "land"]


class FlightMode(Enum):
    """The PX4 flight modes this vehicle simulates, with their PX4 custom-mode encoding."""

    HOLD = "HOLD"
    TAKEOFF = "TAKEOFF"
    LAND = "LAND"
    OFFBOARD = "OFFBOARD"

    @property
    def px4_custom_mode(self) -> int:
        """HEARTBEAT.custom_mode: (sub_mode << 24) | (main_mode << 16)."""
        return _PX4_CUSTOM_MODE[self]


_PX4_CUSTOM_MODE: dict[FlightMode, int] = {
    FlightMode.OFFBOARD: 0x00060000,
    FlightMode.TAKEOFF: 0x02040000,
    FlightMode.HOLD: 0x03040000,
    FlightMode.LAND: 0x06040000,
}


def mode_from_px4(main_mode: int, sub_mode: int) -> FlightMode | None:
    """The simulated mode for a PX4 (main, sub) mode pair, or None if not simulated."""
    if main_mode == 6:
        return FlightMode.OFFBOARD
    if main_mode == 4:
        return {2: FlightMode.TAKEOFF, 3: FlightMode.HOLD, 6: FlightMode.LAND}.get(sub_mode)
    return None


@dataclass(frozen=True)
class GeoPoint:
    """A geodetic position: latitude and longitude in degrees (WGS-84), altitude AMSL in m."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float


PX4_SITL_ORIGIN = GeoPoint(47.397742, 8.545594, 488.0)


def scenario_to_geodetic(xy_m: FloatArray, alt_m: float, origin: GeoPoint) -> GeoPoint:
    """Flat-earth conversion of a scenario-plane point (x east, y north, m; (2,)) at `alt_m`
    above the ground to geodetic, with `origin` the geodetic position of scenario (0, 0)."""
    lat0 = math.radians(origin.lat_deg)
    lat = origin.lat_deg + math.degrees(float(xy_m[1]) / EARTH_RADIUS_M)
    lon = origin.lon_deg + math.degrees(float(xy_m[0]) / (EARTH_RADIUS_M * math.cos(lat0)))
    return GeoPoint(lat, lon, origin.alt_amsl_m + alt_m)


@dataclass(frozen=True)
class AutopilotSettings:
    """Configuration of one simulated vehicle. Units: m, s, Hz, m/s; ports are UDP on 127.0.0.1.

    Attributes:
        index: 0-based vehicle index m; MAVLink system id m + 1.
        offboard_port: Where the offboard client listens; None = 14540 + index.
        gcs_port: Where the ground station listens; None = 14550 + index.
        bind_port: Local port of the offboard link; 0 = ephemeral.
        gcs_bind_port: Local port of the GCS link; 0 = ephemeral.
        geo_origin: Geodetic position of the scenario origin (0, 0) on the ground.
        local_origin_xy_m: Scenario-plane (x east, y north) origin of the local NED frame.
        spawn_xy_m: Scenario-plane start position on the ground; None = the local origin.
        spawn_yaw_rad: Initial heading, rad (0 = north).
        takeoff_alt_m: MIS_TAKEOFF_ALT, altitude above ground of a takeoff without altitude.
        limits: Kinematic limits of the airframe.
        land_speed_mps: MPC_LAND_SPEED, descent rate of LAND near the ground.
        land_slow_below_m: Below this height LAND descends at `land_speed_mps`, above it at the
            maximum descent rate (PX4 MPC_LAND_ALT1).
        offboard_min_rate_hz: Setpoint rate (simulation time) needed to enter OFFBOARD.
        offboard_loss_timeout_s: COM_OF_LOSS_T.
        offboard_loss_action: COM_OBL_RC_ACT: "hold" or "land".
        gcs_loss_timeout_s: COM_DL_LOSS_T.
        gcs_loss_action: NAV_DLL_ACT: "none", "hold" or "land".
        disarm_after_land_s: COM_DISARM_LAND; <= 0 disables auto-disarm after landing.
        disarm_preflight_s: COM_DISARM_PRFLT; <= 0 disables auto-disarm before takeoff.
        telemetry_rate_hz: Rate of ATTITUDE, LOCAL_POSITION_NED and GLOBAL_POSITION_INT.
        status_rate_hz: Rate of SYS_STATUS, EXTENDED_SYS_STATE and GPS_RAW_INT.
        home_rate_hz: Rate of HOME_POSITION.
        heartbeat_keepalive_wall_s: Wall-clock heartbeat period when simulation time stalls;
            None disables it.
        area_min_xy_m: Scenario-plane lower corner of the allowed area (geofence).
        area_max_xy_m: Scenario-plane upper corner of the allowed area.
        min_altitude_m: Lowest altitude a position setpoint may ask for (higher ones clamped up).
        max_altitude_m: Highest altitude a position setpoint may ask for.
        signing: MAVLink 2 signing key of both links; None = no signing (accept unsigned).
    """

    index: int = 0
    offboard_port: int | None = None
    gcs_port: int | None = None
    bind_port: int = 0
    gcs_bind_port: int = 0
    geo_origin: GeoPoint = PX4_SITL_ORIGIN
    local_origin_xy_m: tuple[float, float] = (0.0, 0.0)
    spawn_xy_m: tuple[float, float] | None = None
    spawn_yaw_rad: float = 0.0
    takeoff_alt_m: float = 2.5
    limits: VehicleLimits = field(default_factory=VehicleLimits)
    land_speed_mps: float = 0.7
    land_slow_below_m: float = 10.0
    offboard_min_rate_hz: float = 2.0
    offboard_loss_timeout_s: float = 1.0
    offboard_loss_action: Literal["hold", "land"] = "hold"
    gcs_loss_timeout_s: float = 10.0
    gcs_loss_action: LossAction = "hold"
    disarm_after_land_s: float = 2.0
    disarm_preflight_s: float = 10.0
    telemetry_rate_hz: float = 20.0
    status_rate_hz: float = 2.0
    home_rate_hz: float = 0.5
    heartbeat_keepalive_wall_s: float | None = 1.0
    area_min_xy_m: tuple[float, float] = (-10_000.0, -10_000.0)
    area_max_xy_m: tuple[float, float] = (10_000.0, 10_000.0)
    min_altitude_m: float = 2.0
    max_altitude_m: float = 500.0
    signing: MavlinkSigningKey | None = None

    def __post_init__(self) -> None:
        problems: list[str] = []
        if not 0 <= self.index <= 253:
            problems.append(f"index must be in [0, 253] (got {self.index})")
        for name in ("offboard_port", "gcs_port", "bind_port", "gcs_bind_port"):
            port = getattr(self, name)
            if port is not None and not 0 <= port <= 65535:
                problems.append(f"{name} must be a UDP port (got {port})")
        for name in (
            "takeoff_alt_m",
            "land_speed_mps",
            "offboard_min_rate_hz",
            "offboard_loss_timeout_s",
            "gcs_loss_timeout_s",
            "telemetry_rate_hz",
            "status_rate_hz",
            "home_rate_hz",
            "max_altitude_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                problems.append(f"{name} must be finite and > 0 (got {value})")
        if not (0.0 <= self.min_altitude_m < self.max_altitude_m):
            problems.append(
                f"min_altitude_m must be in [0, max_altitude_m) (got {self.min_altitude_m})"
            )
        if any(lo >= hi for lo, hi in zip(self.area_min_xy_m, self.area_max_xy_m, strict=True)):
            problems.append(
                f"area_min_xy_m {self.area_min_xy_m} must be below area_max_xy_m {self.area_max_xy_m}"
            )
        if self.offboard_loss_action not in ("hold", "land"):
            problems.append(
                f"offboard_loss_action must be hold or land ({self.offboard_loss_action})"
            )
        if self.gcs_loss_action not in ("none", "hold", "land"):
            problems.append(f"gcs_loss_action must be none, hold or land ({self.gcs_loss_action})")
        if self.heartbeat_keepalive_wall_s is not None and not self.heartbeat_keepalive_wall_s > 0:
            problems.append("heartbeat_keepalive_wall_s must be > 0 or None")
        if problems:
            raise ConfigError("\n".join(f"AutopilotSettings: {p}" for p in problems))

    @property
    def system_id(self) -> int:
        """MAVLink system id: index + 1."""
        return self.index + 1

    @property
    def offboard_dest_port(self) -> int:
        """The offboard client's port (14540 + index unless configured)."""
        return OFFBOARD_BASE_PORT + self.index if self.offboard_port is None else self.offboard_port

    @property
    def gcs_dest_port(self) -> int:
        """The ground station's port (14550 + index unless configured)."""
        return GCS_BASE_PORT + self.index if self.gcs_port is None else self.gcs_port


@dataclass(frozen=True)
class AutopilotState:
    """A snapshot of the vehicle, as the world and tests see it.

    Attributes:
        time_s: Simulation time of the snapshot, s.
        position_ned_m: (3,) local NED position, m.
        velocity_ned_mps: (3,) local NED velocity, m/s.
        yaw_rad: Heading, rad.
        position_xy_m: (2,) scenario-plane position (x east, y north), m.
        altitude_m: Height above the ground, m.
        mode: Current flight mode.
        armed: Motors armed.
        landed: On the ground (land detector).
        gcs_lost: No client heartbeat for COM_DL_LOSS_T (after one was heard).
    """

    time_s: float
    position_ned_m: FloatArray
    velocity_ned_mps: FloatArray
    yaw_rad: float
    position_xy_m: FloatArray
    altitude_m: float
    mode: FlightMode
    armed: bool
    landed: bool
    gcs_lost: bool


@dataclass
class _Param:
    value: float
    param_type: int  # MAV_PARAM_TYPE_REAL32 or _INT32
    check: Callable[[float], bool]


def _positive(v: float) -> bool:
    return math.isfinite(v) and v > 0.0


def _finite(v: float) -> bool:
    return math.isfinite(v)


def _same(link: _Link) -> _Link:
    """Protocol factory for `create_datagram_endpoint` (the link is its own protocol)."""
    return link


class _Link(asyncio.DatagramProtocol):
    """One MAVLink UDP link: a socket, its peers and its telemetry schedule."""

    def __init__(self, owner: Autopilot, name: str, default_peer: Address) -> None:
        self.owner = owner
        self.name = name
        self.default_peer = default_peer
        self.peers: dict[Address, None] = {default_peer: None}
        self.transport: asyncio.DatagramTransport | None = None
        self.encoder = new_encoder(owner.system_id, COMPONENT_ID)
        """Packs (and signs) what the link sends; its signing state is shared by the parsers."""
        if owner.settings.signing is not None:
            enable_signing(self.encoder, owner.settings.signing)
        self.intervals_s: dict[int, float] = {}
        self.next_due_s: dict[int, float] = {}
        self.last_heartbeat_wall_s = -math.inf

    # asyncio.DatagramProtocol
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: Address) -> None:
        self.owner._on_datagram(self, data, addr)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable when nobody listens at a peer: normal for UDP telemetry.
        logger.debug("vehicle %d %s link: %s", self.owner.system_id, self.name, exc)

    # sending
    def send(self, msg: Any, to: Address | None = None) -> None:
        """Send one message to `to`, or to every peer of the link."""
        if self.transport is None or self.transport.is_closing():
            return
        if self.owner.radio_silent:
            return
        buf = pack(msg, self.encoder)
        for addr in [to] if to is not None else list(self.peers):
            self.transport.sendto(buf, addr)
        if msg.get_msgId() == mavlink2.MAVLINK_MSG_ID_HEARTBEAT:
            self.last_heartbeat_wall_s = asyncio.get_running_loop().time()

    def add_peer(self, addr: Address) -> None:
        if addr in self.peers:
            return
        if len(self.peers) >= _MAX_PEERS:
            oldest = next(a for a in self.peers if a != self.default_peer)
            del self.peers[oldest]
        self.peers[addr] = None
        logger.info("vehicle %d %s link: new peer %s:%d", self.owner.system_id, self.name, *addr)


class Autopilot:
    """One simulated PX4 multirotor: flight modes, failsafes and a MAVLink 2 endpoint.

    Usage: `ap = Autopilot(settings); await ap.open(); clock.add_tick_callback(ap.step); ...;
    await ap.close()` (or `async with Autopilot(settings) as ap:`).
    """

    def __init__(self, settings: AutopilotSettings) -> None:
        self.settings = settings
        self.rejected: Counter[str] = Counter()
        """Bad input by reason (dropped or clamped)."""
        self.ignored: Counter[str] = Counter()
        """Benign drops by reason (other system/component, unhandled message types)."""
        self._sysid = settings.system_id
        self._origin_xy = np.array(settings.local_origin_xy_m, dtype=np.float64)
        spawn_xy = np.array(
            settings.spawn_xy_m if settings.spawn_xy_m is not None else settings.local_origin_xy_m,
            dtype=np.float64,
        )
        d = spawn_xy - self._origin_xy
        self._vehicle = VehicleState(
            position_ned_m=np.array([d[1], d[0], settings.limits.ground_down_m]),
            yaw_rad=wrap_pi(settings.spawn_yaw_rad),
        )
        self._limits = settings.limits
        self._now_s = 0.0
        self._silence_from_s = self._silence_until_s = math.inf
        self._mode = FlightMode.HOLD
        self._armed = False
        self._landed = True
        self._armed_at_s = 0.0
        self._landed_at_s: float | None = None
        self._hold_ned = self._vehicle.position_ned_m.copy()
        self._land_xy_ned = self._vehicle.position_ned_m[:2].copy()
        self._takeoff_ned = self._vehicle.position_ned_m.copy()
        self._home_ned = self._vehicle.position_ned_m.copy()
        self._offboard_sp: Setpoint | None = None
        self._last_setpoint_s = -math.inf
        self._last_client_heartbeat_s: float | None = None
        self._gcs_lost = False
        self._accel_ned = np.zeros(3)
        self._yaw_rate_rps = 0.0
        self._links: list[_Link] = []
        self._keepalive: asyncio.Task[None] | None = None
        self._warned_types: set[str] = set()
        self._params = self._make_params()
        self._handlers: dict[str, Callable[[_Link, Any, Address], None]] = {
            "HEARTBEAT": self._on_heartbeat,
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "SET_MODE": self._on_set_mode,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_position_target,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "MISSION_REQUEST_LIST": self._on_mission_request_list,
            "MISSION_COUNT": self._on_mission_count,
            "MISSION_CLEAR_ALL": self._on_mission_clear_all,
            "MISSION_REQUEST_INT": self._on_mission_request_item,
            "MISSION_REQUEST": self._on_mission_request_item,
            "PING": self._on_ping,
        }
        self._builders: dict[int, Callable[[], Any]] = {
            mavlink2.MAVLINK_MSG_ID_HEARTBEAT: self._msg_heartbeat,
            mavlink2.MAVLINK_MSG_ID_SYS_STATUS: self._msg_sys_status,
            mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT: self._msg_gps_raw_int,
            mavlink2.MAVLINK_MSG_ID_ATTITUDE: self._msg_attitude,
            mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED: self._msg_local_position_ned,
            mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: self._msg_global_position_int,
            mavlink2.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: self._msg_gps_global_origin,
            mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION: self._msg_autopilot_version,
            mavlink2.MAVLINK_MSG_ID_HOME_POSITION: self._msg_home_position,
            mavlink2.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: self._msg_extended_sys_state,
        }
        self._state = self._snapshot()

    # -- public API --------------------------------------------------------------------------

    @property
    def system_id(self) -> int:
        """MAVLink system id (index + 1)."""
        return self._sysid

    @property
    def state(self) -> AutopilotState:
        """The latest snapshot (replaced after every step and every state change)."""
        return self._state

    @property
    def mode(self) -> FlightMode:
        """Current flight mode."""
        return self._mode

    @property
    def armed(self) -> bool:
        """True when the motors are armed."""
        return self._armed

    @property
    def landed(self) -> bool:
        """True when the land detector says the vehicle is on the ground."""
        return self._landed

    @property
    def signatures_ok(self) -> int:
        """Packets (both links) whose signature was checked and accepted; 0 without signing."""
        return sum(int(link.encoder.signing.goodsig_count) for link in self._links)

    @property
    def offboard_address(self) -> Address:
        """Local (host, port) of the offboard link; valid after `open()`."""
        return self._local_address(0)

    @property
    def gcs_address(self) -> Address:
        """Local (host, port) of the GCS link; valid after `open()`."""
        return self._local_address(1)

    def param(self, name: str) -> float:
        """Current value of a parameter of the simulated param table (KeyError if unknown)."""
        return self._params[name].value

    async def open(self) -> None:
        """Bind both links on 127.0.0.1 and start the wall-clock heartbeat keep-alive."""
        if self._links:
            return
        loop = asyncio.get_running_loop()
        s = self.settings
        for name, bind, dest in (
            ("offboard", s.bind_port, s.offboard_dest_port),
            ("gcs", s.gcs_bind_port, s.gcs_dest_port),
        ):
            link = _Link(self, name, (LOOPBACK, dest))
            try:
                await loop.create_datagram_endpoint(
                    functools.partial(_same, link), local_addr=(LOOPBACK, bind)
                )
            except OSError:
                await self.close()  # do not leave the first link bound
                raise
            self._links.append(link)
            self._init_streams(link)
        logger.info(
            "vehicle %d: offboard link %s:%d -> %d, gcs link %s:%d -> %d",
            self._sysid,
            *self.offboard_address,
            s.offboard_dest_port,
            *self.gcs_address,
            s.gcs_dest_port,
        )
        if s.signing is not None:
            logger.info(
                "vehicle %d: MAVLink signing on (key %s from %s, link id %d)",
                self._sysid,
                s.signing.fingerprint,
                s.signing.source,
                s.signing.link_id,
            )
        if s.heartbeat_keepalive_wall_s is not None:
            self._keepalive = asyncio.create_task(
                self._keepalive_loop(s.heartbeat_keepalive_wall_s),
                name=f"autopilot-{self._sysid}-keepalive",
            )

    async def close(self) -> None:
        """Stop the keep-alive and close both sockets."""
        if self._keepalive is not None:
            self._keepalive.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._keepalive
            self._keepalive = None
        for link in self._links:
            if link.transport is not None:
                link.transport.close()
        self._links = []

    async def __aenter__(self) -> Autopilot:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    def step(self, now_s: float, dt_s: float) -> None:
        """Advance the vehicle to simulation time `now_s` (s) by `dt_s` (s) and send due telemetry.

        Meant as a `SimClock` tick callback: physics, mode logic, failsafes, then telemetry.
        """
        self._now_s = now_s
        self._check_failsafes()
        v0 = self._vehicle
        sp = self._control_setpoint()
        if sp is not None:
            self._vehicle = vehicle_step(v0, sp, self._limits, dt_s)
        v1 = self._vehicle
        self._accel_ned = (v1.velocity_ned_mps - v0.velocity_ned_mps) / dt_s
        self._yaw_rate_rps = wrap_pi(v1.yaw_rad - v0.yaw_rad) / dt_s
        self._update_land_detector()
        self._state = self._snapshot()
        self._send_due_telemetry()

    # -- flight logic ------------------------------------------------------------------------

    def _height_m(self) -> float:
        return float(self._limits.ground_down_m - self._vehicle.position_ned_m[2])

    def _control_setpoint(self) -> Setpoint | None:
        """What the vehicle tracks this step; None = motors off (stay put)."""
        if not self._armed:
            return None
        mode = self._mode
        if self._landed and mode in (FlightMode.HOLD, FlightMode.LAND):
            return None
        if mode is FlightMode.TAKEOFF:
            return Setpoint.hold_at(self._takeoff_ned)
        if mode is FlightMode.HOLD:
            return Setpoint.hold_at(self._hold_ned)
        if mode is FlightMode.LAND:
            rate = (
                self._limits.max_descent_rate_mps
                if self._height_m() > self.settings.land_slow_below_m
                else self._param_value("MPC_LAND_SPEED")
            )
            return Setpoint(
                position_ned_m=np.array([self._land_xy_ned[0], self._land_xy_ned[1], math.nan]),
                velocity_ned_mps=np.array([0.0, 0.0, rate]),
            )
        return self._offboard_sp

    def _set_mode(self, mode: FlightMode, reason: str) -> None:
        if mode is FlightMode.HOLD:
            self._hold_ned = stopping_point(self._vehicle, self._limits)
        elif mode is FlightMode.LAND:
            self._land_xy_ned = stopping_point(self._vehicle, self._limits)[:2]
        if mode is not self._mode:
            logger.info(
                "vehicle %d: mode %s -> %s (%s)", self._sysid, self._mode.value, mode.value, reason
            )
        self._mode = mode
        self._state = self._snapshot()

    def _setpoint_stream_ok(self) -> bool:
        """True when the last setpoint is younger than 1 / offboard_min_rate_hz (sim time).

        PX4 only asks that the last setpoint be younger than COM_OF_LOSS_T; asking for the
        period of a `offboard_min_rate_hz` stream (0.5 s at 2 Hz) is the stricter reading of
        "setpoints must already stream at > 2 Hz", and still lets MAVSDK's usual
        `set_position_ned(); start()` through, since MAVSDK streams from the first set call.
        """
        age_s = self._now_s - self._last_setpoint_s
        return age_s <= 1.0 / self.settings.offboard_min_rate_hz

    def _check_failsafes(self) -> None:
        self._check_offboard_loss()
        self._check_datalink_loss()
        self._check_auto_disarm()

    def _check_offboard_loss(self) -> None:
        if self._mode is not FlightMode.OFFBOARD:
            return
        if self._now_s - self._last_setpoint_s <= self._param_value("COM_OF_LOSS_T"):
            return
        lands = self._param_value("COM_OBL_RC_ACT") == 4
        action = FlightMode.LAND if lands else FlightMode.HOLD
        logger.warning("vehicle %d: offboard setpoints lost, %s", self._sysid, action.value)
        self._set_mode(action, "offboard loss")
        self._statustext(mavlink2.MAV_SEVERITY_WARNING, f"Offboard lost: {action.value}")

    def _check_datalink_loss(self) -> None:
        last = self._last_client_heartbeat_s
        if last is None or self._gcs_lost:
            return
        silent_s = self._now_s - last
        if silent_s <= self._param_value("COM_DL_LOSS_T"):
            return
        self._gcs_lost = True
        act = int(self._param_value("NAV_DLL_ACT"))
        action = {1: FlightMode.HOLD, 3: FlightMode.LAND}.get(act)
        logger.warning(
            "vehicle %d: no client heartbeat for %.1f s, action %s",
            self._sysid,
            silent_s,
            action.value if action else "none",
        )
        airborne = self._armed and not self._landed
        if action is not None and airborne and self._mode not in (FlightMode.LAND, action):
            self._set_mode(action, "datalink loss")
        self._statustext(mavlink2.MAV_SEVERITY_CRITICAL, "Connection to ground station lost")
        self._state = self._snapshot()

    def _check_auto_disarm(self) -> None:
        if not (self._armed and self._landed):
            return
        now = self._now_s
        if self._landed_at_s is not None:
            delay = self._param_value("COM_DISARM_LAND")
            if delay > 0 and now - self._landed_at_s >= delay:
                self._disarm("landed")
        else:
            delay = self._param_value("COM_DISARM_PRFLT")
            if delay > 0 and now - self._armed_at_s >= delay:
                self._disarm("no takeoff after arming")

    def _update_land_detector(self) -> None:
        height = self._height_m()
        v_down = float(self._vehicle.velocity_ned_mps[2])
        if self._landed and self._armed and height > _AIRBORNE_ALT_M:
            self._landed = False
            self._landed_at_s = None
            logger.info("vehicle %d: airborne", self._sysid)
        elif not self._landed and height < _LANDED_ALT_M and v_down >= -0.05:
            self._landed = True
            self._landed_at_s = self._now_s
            logger.info("vehicle %d: landed", self._sysid)
        to_go_m = abs(float(self._takeoff_ned[2] - self._vehicle.position_ned_m[2]))
        if self._mode is FlightMode.TAKEOFF and not self._landed and to_go_m < _TAKEOFF_DONE_M:
            self._set_mode(FlightMode.HOLD, "takeoff complete")

    def _arm(self) -> int:
        if self._armed:
            return _RESULT_ACCEPTED
        if not self._landed:
            return _RESULT_DENIED
        self._armed = True
        self._armed_at_s = self._now_s
        self._landed_at_s = None
        self._home_ned = self._vehicle.position_ned_m.copy()
        if self._mode in (FlightMode.LAND, FlightMode.TAKEOFF):
            self._set_mode(FlightMode.HOLD, "armed")
        logger.info("vehicle %d: armed", self._sysid)
        self._state = self._snapshot()
        return _RESULT_ACCEPTED

    def _disarm(self, reason: str) -> int:
        if not self._armed:
            return _RESULT_ACCEPTED
        if not self._landed:
            return _RESULT_DENIED
        self._armed = False
        self._vehicle = replace(self._vehicle, velocity_ned_mps=np.zeros(3))
        logger.info("vehicle %d: disarmed (%s)", self._sysid, reason)
        self._state = self._snapshot()
        return _RESULT_ACCEPTED

    def _takeoff(self, alt_amsl_m: float) -> int:
        if not self._armed:
            return _RESULT_DENIED
        home_amsl = self.settings.geo_origin.alt_amsl_m + float(
            self._limits.ground_down_m - self._home_ned[2]
        )
        height = (
            alt_amsl_m - home_amsl
            if math.isfinite(alt_amsl_m)
            else self._param_value("MIS_TAKEOFF_ALT")
        )
        height = min(max(height, self.settings.min_altitude_m), self.settings.max_altitude_m)
        xy = stopping_point(self._vehicle, self._limits)[:2]
        self._takeoff_ned = np.array([xy[0], xy[1], self._limits.ground_down_m - height])
        self._set_mode(FlightMode.TAKEOFF, f"takeoff to {height:.1f} m")
        return _RESULT_ACCEPTED

    def _request_mode(self, mode: FlightMode) -> int:
        if mode is FlightMode.OFFBOARD:
            if not self._setpoint_stream_ok():
                logger.warning("vehicle %d: OFFBOARD denied, no setpoint stream", self._sysid)
                return _RESULT_DENIED
            self._set_mode(FlightMode.OFFBOARD, "requested")
            return _RESULT_ACCEPTED
        if mode is FlightMode.TAKEOFF:
            return self._takeoff(math.nan)
        self._set_mode(mode, "requested")
        return _RESULT_ACCEPTED

    # -- receiving ---------------------------------------------------------------------------

    def _reject(self, reason: str, detail: str) -> None:
        self.rejected[reason] += 1
        n = self.rejected[reason]
        if n <= 5 or n % 100 == 0:
            logger.warning("vehicle %d: rejected (%s, #%d): %s", self._sysid, reason, n, detail)

    @property
    def radio_silent(self) -> bool:
        """True inside a `silence_radio` window: nothing is sent and everything heard is lost."""
        return self._silence_from_s <= self._now_s < self._silence_until_s

    def silence_radio(self, from_s: float, duration_s: float) -> None:
        """Fault injection: the vehicle's MAVLink radio (both links) is dead from simulation time
        `from_s` for `duration_s` seconds. The vehicle flies on under its own failsafes
        (offboard loss after COM_OF_LOSS_T, lost GCS after COM_DL_LOSS_T)."""
        if not (math.isfinite(from_s) and math.isfinite(duration_s) and duration_s >= 0):
            raise ValueError(
                f"radio silence needs finite from_s and duration_s >= 0, got {from_s}, {duration_s}"
            )
        self._silence_from_s, self._silence_until_s = from_s, from_s + duration_s
        logger.warning(
            "vehicle %d: radio silence from t = %.2f s for %.2f s",
            self._sysid,
            from_s,
            duration_s,
        )

    def _on_datagram(self, link: _Link, data: bytes, addr: Address) -> None:
        if self.radio_silent:
            self.rejected["radio silence"] += 1
            return
        # A fresh parser per datagram: UDP keeps packets whole, so nothing carries over and a
        # truncated or corrupt packet cannot swallow the next datagram.
        # The parsers of a link share its signing state (key, streams' newest timestamps).
        parser = new_parser(link.encoder)
        refresh_signing_clock(parser)
        try:
            msgs = parser.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises on some malformed input even when robust
            self._reject("parse_error", f"{exc} from {addr}")
            return
        for msg in msgs:
            self._dispatch(link, msg, addr)
        if parser.buf_len() > 0:
            self._reject("truncated", f"{parser.buf_len()} bytes left over from {addr}")

    def _dispatch(self, link: _Link, msg: Any, addr: Address) -> None:
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            reason = str(msg.reason)
            refused = signature_failure(msg, link.encoder)
            if refused is not None:
                self._reject(refused, f"{packet_origin(bytes(msg.data))} from {addr}")
            elif "CRC" in reason:
                self._reject("bad_crc", f"{reason} from {addr}")
            elif "prefix" in reason.lower():
                self._reject("garbage", f"{len(msg.data)} bytes from {addr}")
            else:
                self._reject("bad_data", f"{reason} from {addr}")
            return
        if mtype.startswith("UNKNOWN_"):
            self._reject("unknown_message", f"message id {mtype[8:]} from {addr}")
            return
        if msg.get_srcSystem() == self._sysid:
            self.ignored["own_system"] += 1
            return
        target_system = getattr(msg, "target_system", 0)
        if target_system not in (0, self._sysid):
            self.ignored["other_system"] += 1
            return
        if getattr(msg, "target_component", 0) not in (0, COMPONENT_ID):
            self.ignored["other_component"] += 1
            return
        link.add_peer(addr)
        handler = self._handlers.get(mtype)
        if handler is None:
            self.ignored[f"unhandled:{mtype}"] += 1
            if mtype not in self._warned_types:
                self._warned_types.add(mtype)
                logger.info("vehicle %d: ignoring %s messages", self._sysid, mtype)
            return
        try:
            handler(link, msg, addr)
        except Exception:
            self.rejected["handler_error"] += 1
            logger.exception("vehicle %d: handler for %s failed", self._sysid, mtype)

    def _on_heartbeat(self, link: _Link, msg: Any, addr: Address) -> None:
        if self._gcs_lost:
            logger.info("vehicle %d: client heartbeat regained on %s link", self._sysid, link.name)
            self._gcs_lost = False
            self._state = self._snapshot()
        self._last_client_heartbeat_s = self._now_s

    def _on_ping(self, link: _Link, msg: Any, addr: Address) -> None:
        if msg.target_system != 0:
            return  # a reply to a ping of ours (we send none)
        link.send(
            mavlink2.MAVLink_ping_message(
                msg.time_usec, msg.seq, msg.get_srcSystem(), msg.get_srcComponent()
            ),
            addr,
        )

    def _ack(self, link: _Link, msg: Any, addr: Address, command: int, result: int) -> None:
        link.send(
            mavlink2.MAVLink_command_ack_message(
                command, result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
            ),
            addr,
        )

    def _on_command_long(self, link: _Link, msg: Any, addr: Address) -> None:
        params = (
            msg.param1,
            msg.param2,
            msg.param3,
            msg.param4,
            msg.param5,
            msg.param6,
            msg.param7,
        )
        self._on_command(link, msg, addr, int(msg.command), tuple(float(p) for p in params))

    def _on_command_int(self, link: _Link, msg: Any, addr: Address) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z)
        self._on_command(link, msg, addr, int(msg.command), tuple(float(p) for p in params))

    def _on_command(
        self, link: _Link, msg: Any, addr: Address, command: int, p: tuple[float, ...]
    ) -> None:
        followup: Any = None
        n_ints = _INTEGER_PARAMS.get(command, 0)
        if not all(math.isfinite(x) and abs(x) < 2**31 for x in p[:n_ints]):
            # NaN, inf or absurd where an integer is expected: refused, as PX4 does.
            self._reject("bad_command_param", f"command {command} {p[:n_ints]} from {addr}")
            self._ack(link, msg, addr, command, _RESULT_DENIED)
            return
        if command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
            result = self._arm() if p[0] >= 0.5 else self._disarm("commanded")
        elif command == mavlink2.MAV_CMD_NAV_TAKEOFF:
            result = self._takeoff(p[6])
        elif command == mavlink2.MAV_CMD_NAV_LAND:
            result = self._request_mode(FlightMode.LAND)
        elif command == mavlink2.MAV_CMD_DO_SET_MODE:
            result = self._command_set_mode(int(p[0]), int(p[1]), int(p[2]))
        elif command == mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._set_message_interval(link, int(p[0]), p[1])
        elif command == mavlink2.MAV_CMD_REQUEST_MESSAGE:
            builder = self._builders.get(int(p[0]))
            result = _RESULT_ACCEPTED if builder else _RESULT_UNSUPPORTED
            followup = builder() if builder else None
        elif command == mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            result = _RESULT_ACCEPTED
            followup = self._msg_autopilot_version()
        elif command == mavlink2.MAV_CMD_GET_HOME_POSITION:
            result = _RESULT_ACCEPTED
            followup = self._msg_home_position()
        else:
            result = _RESULT_UNSUPPORTED
        level = logging.INFO if result == _RESULT_ACCEPTED else logging.WARNING
        logger.log(level, "vehicle %d: command %d %s -> result %d", self._sysid, command, p, result)
        self._ack(link, msg, addr, command, result)
        if followup is not None:
            link.send(followup, addr)

    def _command_set_mode(self, base_mode: int, main_mode: int, sub_mode: int) -> int:
        if not base_mode & mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return _RESULT_UNSUPPORTED
        mode = mode_from_px4(main_mode, sub_mode)
        if mode is None:
            return _RESULT_UNSUPPORTED
        return self._request_mode(mode)

    def _on_set_mode(self, link: _Link, msg: Any, addr: Address) -> None:
        custom = int(msg.custom_mode)
        result = self._command_set_mode(
            int(msg.base_mode), (custom >> 16) & 0xFF, (custom >> 24) & 0xFF
        )
        self._ack(link, msg, addr, mavlink2.MAV_CMD_DO_SET_MODE, result)

    def _set_message_interval(self, link: _Link, msg_id: int, interval_us: float) -> int:
        if msg_id not in self._builders or not math.isfinite(interval_us):
            return _RESULT_UNSUPPORTED
        if interval_us < 0:
            link.intervals_s.pop(msg_id, None)
        elif interval_us == 0:
            default = self._default_intervals().get(msg_id)
            if default is None:
                link.intervals_s.pop(msg_id, None)
            else:
                link.intervals_s[msg_id] = default
        else:
            link.intervals_s[msg_id] = interval_us * 1e-6
        link.next_due_s[msg_id] = self._now_s
        return _RESULT_ACCEPTED

    def _on_position_target(self, link: _Link, msg: Any, addr: Address) -> None:
        if msg.coordinate_frame != mavlink2.MAV_FRAME_LOCAL_NED:
            self._reject("unsupported_frame", f"frame {msg.coordinate_frame} from {addr}")
            return
        mask = int(msg.type_mask)
        raw_p = (float(msg.x), float(msg.y), float(msg.z))
        raw_v = (float(msg.vx), float(msg.vy), float(msg.vz))
        use_p = [not mask & bit for bit in (1, 2, 4)]
        use_v = [not mask & bit for bit in (8, 16, 32)]
        if not any(use_p) and not any(use_v):
            self._reject("unsupported_type_mask", f"type_mask 0x{mask:03X} from {addr}")
            return
        used = [x for x, u in zip(raw_p + raw_v, use_p + use_v, strict=True) if u]
        if not all(math.isfinite(x) for x in used):
            self._reject("non_finite_setpoint", f"{raw_p} {raw_v} mask 0x{mask:03X} from {addr}")
            return
        pos = np.array([x if u else math.nan for x, u in zip(raw_p, use_p, strict=True)])
        vel = np.array([x if u else math.nan for x, u in zip(raw_v, use_v, strict=True)])
        self._clamp_position_setpoint(pos, addr)
        yaw = (
            float(msg.yaw) if not mask & mavlink2.POSITION_TARGET_TYPEMASK_YAW_IGNORE else math.nan
        )
        yaw_rate = (
            float(msg.yaw_rate)
            if not mask & mavlink2.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
            else math.nan
        )
        self._offboard_sp = Setpoint(
            position_ned_m=pos,
            velocity_ned_mps=vel,
            yaw_rad=yaw if math.isfinite(yaw) else math.nan,
            yaw_rate_rps=yaw_rate if math.isfinite(yaw_rate) else math.nan,
        )
        self._last_setpoint_s = self._now_s

    def _clamp_position_setpoint(self, pos: FloatArray, addr: Address) -> None:
        """Clamp a local NED position setpoint (3,) in place to the area and altitude band."""
        s = self.settings
        for axis_ned, axis_xy in ((0, 1), (1, 0)):
            if math.isnan(pos[axis_ned]):
                continue
            scn = pos[axis_ned] + self._origin_xy[axis_xy]
            lo, hi = s.area_min_xy_m[axis_xy], s.area_max_xy_m[axis_xy]
            if not lo <= scn <= hi:
                self._reject(
                    "out_of_area", f"{'xy'[axis_xy]} = {scn:.1f} m outside [{lo}, {hi}] from {addr}"
                )
                pos[axis_ned] = min(max(scn, lo), hi) - self._origin_xy[axis_xy]
        if not math.isnan(pos[2]):
            ground = self._limits.ground_down_m
            alt = ground - pos[2]
            if alt < s.min_altitude_m:
                reason = "below_ground" if alt < 0.0 else "below_min_altitude"
                self._reject(reason, f"altitude {alt:.1f} m < {s.min_altitude_m} m from {addr}")
                pos[2] = ground - s.min_altitude_m
            elif alt > s.max_altitude_m:
                self._reject(
                    "above_max_altitude", f"altitude {alt:.1f} m > {s.max_altitude_m} m from {addr}"
                )
                pos[2] = ground - s.max_altitude_m

    # -- parameters --------------------------------------------------------------------------

    def _make_params(self) -> dict[str, _Param]:
        s = self.settings
        lim = s.limits
        real, int32 = mavlink2.MAV_PARAM_TYPE_REAL32, mavlink2.MAV_PARAM_TYPE_INT32
        obl = {"hold": 5.0, "land": 4.0}[s.offboard_loss_action]
        dll = {"none": 0.0, "hold": 1.0, "land": 3.0}[s.gcs_loss_action]
        return {
            "MAV_SYS_ID": _Param(float(self._sysid), int32, lambda v: v == self._sysid),
            "MIS_TAKEOFF_ALT": _Param(s.takeoff_alt_m, real, _positive),
            "COM_OF_LOSS_T": _Param(s.offboard_loss_timeout_s, real, _positive),
            "COM_OBL_RC_ACT": _Param(obl, int32, lambda v: v in (4.0, 5.0)),
            "COM_DL_LOSS_T": _Param(s.gcs_loss_timeout_s, real, _positive),
            "NAV_DLL_ACT": _Param(dll, int32, lambda v: v in (0.0, 1.0, 3.0)),
            "COM_DISARM_LAND": _Param(s.disarm_after_land_s, real, _finite),
            "COM_DISARM_PRFLT": _Param(s.disarm_preflight_s, real, _finite),
            "MPC_XY_VEL_MAX": _Param(lim.max_horizontal_speed_mps, real, _positive),
            "MPC_ACC_HOR_MAX": _Param(lim.max_horizontal_accel_mps2, real, _positive),
            "MPC_Z_VEL_MAX_UP": _Param(lim.max_climb_rate_mps, real, _positive),
            "MPC_Z_VEL_MAX_DN": _Param(lim.max_descent_rate_mps, real, _positive),
            "MPC_LAND_SPEED": _Param(s.land_speed_mps, real, _positive),
        }

    def _param_value(self, name: str) -> float:
        return self._params[name].value

    def _apply_param(self, name: str) -> None:
        """Push a changed parameter into the live limits."""
        fields = {
            "MPC_XY_VEL_MAX": "max_horizontal_speed_mps",
            "MPC_ACC_HOR_MAX": "max_horizontal_accel_mps2",
            "MPC_Z_VEL_MAX_UP": "max_climb_rate_mps",
            "MPC_Z_VEL_MAX_DN": "max_descent_rate_mps",
        }
        if name in fields:
            self._limits = replace(self._limits, **{fields[name]: self._params[name].value})

    def _param_value_msg(self, name: str) -> Any:
        names = list(self._params)
        p = self._params[name]
        if p.param_type == mavlink2.MAV_PARAM_TYPE_INT32:
            # PX4 encodes integer parameters bytewise in the float field.
            wire = struct.unpack("<f", struct.pack("<i", int(p.value)))[0]
        else:
            wire = p.value
        return mavlink2.MAVLink_param_value_message(
            name.encode("ascii"), wire, p.param_type, len(names), names.index(name)
        )

    @staticmethod
    def _param_name(raw: Any) -> str:
        if isinstance(raw, bytes):
            raw = raw.split(b"\x00", 1)[0].decode("ascii", errors="replace")
        return str(raw).rstrip("\x00")

    def _on_param_request_list(self, link: _Link, msg: Any, addr: Address) -> None:
        for name in self._params:
            link.send(self._param_value_msg(name), addr)

    def _on_param_request_read(self, link: _Link, msg: Any, addr: Address) -> None:
        names = list(self._params)
        index = int(msg.param_index)
        if index >= 0:
            if index >= len(names):
                self._reject("unknown_param", f"index {index} from {addr}")
                return
            name = names[index]
        else:
            name = self._param_name(msg.param_id)
            if name not in self._params:
                self._reject("unknown_param", f"{name!r} from {addr}")
                return
        link.send(self._param_value_msg(name), addr)

    def _on_param_set(self, link: _Link, msg: Any, addr: Address) -> None:
        name = self._param_name(msg.param_id)
        p = self._params.get(name)
        if p is None:
            self._reject("unknown_param", f"set {name!r} from {addr}")
            return
        wire = float(msg.param_value)
        if (
            p.param_type == mavlink2.MAV_PARAM_TYPE_INT32
            and msg.param_type != mavlink2.MAV_PARAM_TYPE_REAL32
        ):
            value = float(struct.unpack("<i", struct.pack("<f", wire))[0])
        else:
            value = wire
        if p.check(value):
            p.value = value
            self._apply_param(name)
            logger.info("vehicle %d: param %s = %g", self._sysid, name, value)
        else:
            self._reject("bad_param_value", f"{name} = {value!r} from {addr}")
        # Answered either way with the value in force, as PX4 does.
        link.send(self._param_value_msg(name), addr)

    # -- mission protocol (no mission support: an empty plan) ----------------------------------

    def _on_mission_request_list(self, link: _Link, msg: Any, addr: Address) -> None:
        link.send(
            mavlink2.MAVLink_mission_count_message(
                msg.get_srcSystem(), msg.get_srcComponent(), 0, getattr(msg, "mission_type", 0)
            ),
            addr,
        )

    def _mission_ack(self, link: _Link, msg: Any, addr: Address, result: int) -> None:
        link.send(
            mavlink2.MAVLink_mission_ack_message(
                msg.get_srcSystem(), msg.get_srcComponent(), result, getattr(msg, "mission_type", 0)
            ),
            addr,
        )

    def _on_mission_count(self, link: _Link, msg: Any, addr: Address) -> None:
        ok = int(msg.count) == 0
        self._mission_ack(
            link,
            msg,
            addr,
            mavlink2.MAV_MISSION_ACCEPTED if ok else mavlink2.MAV_MISSION_UNSUPPORTED,
        )

    def _on_mission_clear_all(self, link: _Link, msg: Any, addr: Address) -> None:
        self._mission_ack(link, msg, addr, mavlink2.MAV_MISSION_ACCEPTED)

    def _on_mission_request_item(self, link: _Link, msg: Any, addr: Address) -> None:
        self._mission_ack(link, msg, addr, mavlink2.MAV_MISSION_INVALID_SEQUENCE)

    # -- telemetry ---------------------------------------------------------------------------

    def _default_intervals(self) -> dict[int, float]:
        s = self.settings
        fast, status = 1.0 / s.telemetry_rate_hz, 1.0 / s.status_rate_hz
        return {
            mavlink2.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
            mavlink2.MAVLINK_MSG_ID_SYS_STATUS: status,
            mavlink2.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: status,
            mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT: status,
            mavlink2.MAVLINK_MSG_ID_ATTITUDE: fast,
            mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED: fast,
            mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: fast,
            mavlink2.MAVLINK_MSG_ID_HOME_POSITION: 1.0 / s.home_rate_hz,
        }

    def _init_streams(self, link: _Link) -> None:
        link.intervals_s = self._default_intervals()
        link.next_due_s = dict.fromkeys(link.intervals_s, self._now_s)

    def _send_due_telemetry(self) -> None:
        now = self._now_s
        built: dict[int, Any] = {}
        for link in self._links:
            for msg_id, interval in link.intervals_s.items():
                due = link.next_due_s.get(msg_id, now)
                if now + 1e-9 < due:
                    continue
                if msg_id not in built:
                    built[msg_id] = self._builders[msg_id]()
                link.send(built[msg_id])
                due += interval
                link.next_due_s[msg_id] = due if due > now else now + interval

    async def _keepalive_loop(self, period_s: float) -> None:
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(period_s / 2.0)
            for link in self._links:
                if loop.time() - link.last_heartbeat_wall_s >= period_s:
                    link.send(self._msg_heartbeat())

    def _statustext(self, severity: int, text: str) -> None:
        msg = mavlink2.MAVLink_statustext_message(severity, text.encode("ascii")[:50], 0, 0)
        for link in self._links:
            link.send(msg)

    def _time_boot_ms(self) -> int:
        return round(self._now_s * 1000.0) & 0xFFFFFFFF

    def _geodetic(self, ned: FloatArray) -> GeoPoint:
        xy = self._origin_xy + np.array([ned[1], ned[0]])
        return scenario_to_geodetic(
            xy, float(self._limits.ground_down_m - ned[2]), self.settings.geo_origin
        )

    def _msg_heartbeat(self) -> Any:
        base = (
            mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            | mavlink2.MAV_MODE_FLAG_AUTO_ENABLED
            | mavlink2.MAV_MODE_FLAG_GUIDED_ENABLED
            | mavlink2.MAV_MODE_FLAG_STABILIZE_ENABLED
        )
        if self._armed:
            base |= mavlink2.MAV_MODE_FLAG_SAFETY_ARMED
        status = mavlink2.MAV_STATE_ACTIVE if self._armed else mavlink2.MAV_STATE_STANDBY
        return mavlink2.MAVLink_heartbeat_message(
            mavlink2.MAV_TYPE_QUADROTOR,
            mavlink2.MAV_AUTOPILOT_PX4,
            base,
            self._mode.px4_custom_mode,
            status,
            3,
        )

    def _msg_sys_status(self) -> Any:
        sensors = (
            mavlink2.MAV_SYS_STATUS_SENSOR_3D_GYRO
            | mavlink2.MAV_SYS_STATUS_SENSOR_3D_ACCEL
            | mavlink2.MAV_SYS_STATUS_SENSOR_3D_MAG
            | mavlink2.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
            | mavlink2.MAV_SYS_STATUS_SENSOR_GPS
            | mavlink2.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | mavlink2.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
            | mavlink2.MAV_SYS_STATUS_SENSOR_YAW_POSITION
            | mavlink2.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
            | mavlink2.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
            | mavlink2.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | mavlink2.MAV_SYS_STATUS_AHRS
            | mavlink2.MAV_SYS_STATUS_SENSOR_BATTERY
            | mavlink2.MAV_SYS_STATUS_PREARM_CHECK
        )
        return mavlink2.MAVLink_sys_status_message(
            sensors, sensors, sensors, 150, 16200, -1, 100, 0, 0, 0, 0, 0, 0, 0, 0, 0
        )

    def _msg_extended_sys_state(self) -> Any:
        if self._landed:
            landed = mavlink2.MAV_LANDED_STATE_ON_GROUND
        elif self._mode is FlightMode.TAKEOFF:
            landed = mavlink2.MAV_LANDED_STATE_TAKEOFF
        elif self._mode is FlightMode.LAND:
            landed = mavlink2.MAV_LANDED_STATE_LANDING
        else:
            landed = mavlink2.MAV_LANDED_STATE_IN_AIR
        return mavlink2.MAVLink_extended_sys_state_message(mavlink2.MAV_VTOL_STATE_MC, landed)

    def _msg_attitude(self) -> Any:
        a = self._accel_ned
        yaw = self._vehicle.yaw_rad
        a_fwd = a[0] * math.cos(yaw) + a[1] * math.sin(yaw)
        a_right = -a[0] * math.sin(yaw) + a[1] * math.cos(yaw)
        pitch = -math.atan2(a_fwd, GRAVITY_MPS2)
        roll = math.atan2(a_right, GRAVITY_MPS2)
        return mavlink2.MAVLink_attitude_message(
            self._time_boot_ms(), roll, pitch, yaw, 0.0, 0.0, self._yaw_rate_rps
        )

    def _msg_local_position_ned(self) -> Any:
        p, v = self._vehicle.position_ned_m, self._vehicle.velocity_ned_mps
        return mavlink2.MAVLink_local_position_ned_message(
            self._time_boot_ms(), p[0], p[1], p[2], v[0], v[1], v[2]
        )

    def _msg_global_position_int(self) -> Any:
        p, v = self._vehicle.position_ned_m, self._vehicle.velocity_ned_mps
        geo = self._geodetic(p)
        rel_alt_m = float(self._home_ned[2] - p[2])
        hdg = round(math.degrees(self._vehicle.yaw_rad) * 100.0) % 36000
        return mavlink2.MAVLink_global_position_int_message(
            self._time_boot_ms(),
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            round(rel_alt_m * 1000.0),
            round(v[0] * 100.0),
            round(v[1] * 100.0),
            round(v[2] * 100.0),
            hdg,
        )

    def _msg_gps_raw_int(self) -> Any:
        p, v = self._vehicle.position_ned_m, self._vehicle.velocity_ned_mps
        geo = self._geodetic(p)
        speed = float(np.hypot(v[0], v[1]))
        cog = round(math.degrees(math.atan2(v[1], v[0])) * 100.0) % 36000 if speed > 0.1 else 65535
        return mavlink2.MAVLink_gps_raw_int_message(
            round(self._now_s * 1e6),
            mavlink2.GPS_FIX_TYPE_3D_FIX,
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            70,
            90,
            round(speed * 100.0),
            cog,
            14,
        )

    def _msg_gps_global_origin(self) -> Any:
        geo = self._geodetic(np.array([0.0, 0.0, self._limits.ground_down_m]))
        return mavlink2.MAVLink_gps_global_origin_message(
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            round(self._now_s * 1e6),
        )

    def _msg_home_position(self) -> Any:
        h = self._home_ned
        geo = self._geodetic(h)
        return mavlink2.MAVLink_home_position_message(
            round(geo.lat_deg * 1e7),
            round(geo.lon_deg * 1e7),
            round(geo.alt_amsl_m * 1000.0),
            h[0],
            h[1],
            h[2],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            0.0,
            0.0,
            round(self._now_s * 1e6),
        )

    def _msg_autopilot_version(self) -> Any:
        caps = (
            mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | mavlink2.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            | mavlink2.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | mavlink2.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        )
        version = (1 << 24) | (15 << 16) | (0 << 8) | 255  # "v1.15.0, official"
        return mavlink2.MAVLink_autopilot_version_message(
            caps, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x1500 + self._sysid, [0] * 18
        )

    # -- snapshots ---------------------------------------------------------------------------

    def _snapshot(self) -> AutopilotState:
        v = self._vehicle
        p = v.position_ned_m.copy()
        xy = self._origin_xy + np.array([p[1], p[0]])
        return AutopilotState(
            time_s=self._now_s,
            position_ned_m=p,
            velocity_ned_mps=v.velocity_ned_mps.copy(),
            yaw_rad=v.yaw_rad,
            position_xy_m=xy,
            altitude_m=self._height_m(),
            mode=self._mode,
            armed=self._armed,
            landed=self._landed,
            gcs_lost=self._gcs_lost,
        )

    def _local_address(self, i: int) -> Address:
        if len(self._links) <= i or self._links[i].transport is None:
            raise RuntimeError("Autopilot is not open")
        transport = self._links[i].transport
        assert transport is not None
        host, port = transport.get_extra_info("sockname")[:2]
        return (str(host), int(port))
