"""MavlinkLink: one vehicle's MAVLink 2 link over UDP; the only module of isac_mission that imports
pymavlink.

The link works like MAVSDK's `udpin://127.0.0.1:14540+m`: it binds 127.0.0.1:(base + m), learns
the vehicle's address from the first packet of the vehicle's system, and replies there. It is an
`asyncio.DatagramProtocol`; each datagram goes through one pymavlink parser (`parse_buffer`), and
every message is dispatched to the handlers registered for its type (a dict keyed by message
type). A handler that raises is logged and counted in `errors["handler_error"]`; it never stops
the link. A message type without a handler is noted once in the log and counted in `ignored`.
Bad input is counted per reason in `errors`: `garbage` (bytes that are not MAVLink), `bad_crc`,
`bad_data` (other pymavlink complaints), `truncated` (a datagram ending inside a packet),
`unknown_message` (a message id outside the common dialect), `parse_error` (pymavlink raised),
`foreign_address` (a packet in the vehicle's name from another address than the vehicle's:
the address is learnt from the vehicle's HEARTBEAT and moves only after the link was lost).

MAVLink 2 signing (`signing=` a `MavlinkSigningKey`, from the scenario's
`security.mavlink_signing`): every message we send is signed, with timestamps that follow the wall
clock; every packet without a valid signature is dropped and counted in `errors` as `unsigned`
(no signature, or MAVLink 1), `bad_signature` (another key, or altered) or `replayed` (our key,
but a timestamp not newer than its stream's last). pymavlink does the checks (`enable_signing`);
`_MAVLink` fixes its order so a forged packet cannot poison a stream's timestamp. Off by default:
nothing is signed and everything is accepted, as MAVSDK and PX4 SITL expect.

Vehicle state (`VehicleStatus`, a snapshot taken by `status()`): local NED position and velocity
(LOCAL_POSITION_NED), heading (ATTITUDE), home altitude AMSL (GLOBAL_POSITION_INT), the PX4 mode
name decoded from HEARTBEAT.custom_mode (`px4_mode_name`), armed (HEARTBEAT base_mode), landed
state (EXTENDED_SYS_STATE), and the time of the last HEARTBEAT. Times come from the `clock`
callable given to the link (the bridge passes its simulation time, so "lost" is judged in
simulation seconds, like every other timeout of the service). The link is *lost* when no
HEARTBEAT has been heard for `lost_after_s` (or never).

Outgoing messages come from the pure builder functions below (`gcs_heartbeat`, `arm_command`,
`takeoff_command`, `land_command`, `set_mode_command`, `position_target_local_ned`, ...), which
return pymavlink message objects and can be checked without a socket. `MavlinkLink.command()`
sends a COMMAND_LONG and waits for its COMMAND_ACK (wall-clock timeout per attempt, with
retries that bump the `confirmation` field as the MAVLink command protocol asks); a final result
other than ACCEPTED, or no answer, raises `LinkError` naming the command and the result.
IN_PROGRESS extends the wait without resending.

Frames and units: MAV_FRAME_LOCAL_NED (north, east, down), m, m/s, rad; arrays are float64 (3,).

pymavlink's dialect and protocol version are chosen by environment variables read at import:
MAVLINK20=1 and MAVLINK_DIALECT=common are set (if unset) before pymavlink is imported, and the
common MAVLink 2 dialect module is imported directly.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import math
import os
import struct
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final, Literal, cast

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink.dialects.v20 import common as mavlink2

from isac_mission.config import MavlinkSigningKey
from isac_mission.errors import LinkError
from isac_mission.types import FloatArray

log = logging.getLogger(__name__)

LOOPBACK: Final = "127.0.0.1"
OFFBOARD_BASE_PORT: Final = 14540
"""PX4 SITL instance m talks to its offboard client on UDP 14540 + m."""
GCS_SYSTEM_ID: Final = 255
"""Our MAVLink system id (a ground station's, as QGroundControl)."""
GCS_COMPONENT_ID: Final = mavlink2.MAV_COMP_ID_MISSIONPLANNER  # 190
AUTOPILOT_COMPONENT_ID: Final = mavlink2.MAV_COMP_ID_AUTOPILOT1  # 1

Address = tuple[str, int]
Handler = Callable[[Any], None]
"""Called with one parsed pymavlink message."""

# --------------------------------------------------------------------------- PX4 custom modes

PX4_MAIN_MODES: Final[dict[int, str]] = {
    1: "manual",
    2: "altctl",
    3: "posctl",
    4: "auto",
    5: "acro",
    6: "offboard",
    7: "stabilized",
    8: "rattitude",
}
"""PX4 main modes (custom_mode bits 16-23)."""
PX4_AUTO_SUB_MODES: Final[dict[int, str]] = {
    1: "ready",
    2: "takeoff",
    3: "hold",  # AUTO.LOITER
    4: "mission",
    5: "rtl",
    6: "land",
    8: "follow_target",
    9: "precland",
    10: "vtol_takeoff",
}
"""PX4 AUTO sub-modes (custom_mode bits 24-31)."""
PX4_MAIN_AUTO: Final = 4
PX4_MAIN_OFFBOARD: Final = 6
PX4_SUB_HOLD: Final = 3


def px4_custom_mode(main_mode: int, sub_mode: int = 0) -> int:
    """HEARTBEAT.custom_mode of a PX4 mode: (sub_mode << 24) | (main_mode << 16)."""
    return ((sub_mode & 0xFF) << 24) | ((main_mode & 0xFF) << 16)


def px4_mode_name(custom_mode: int) -> str:
    """The PX4 mode of a HEARTBEAT.custom_mode, lower case.

    "offboard", "hold", "takeoff", "land", "mission", "rtl", "manual", "posctl", ... ; an AUTO
    mode with an unknown sub-mode is "auto"; an unknown main mode is "unknown".
    """
    main = (custom_mode >> 16) & 0xFF
    sub = (custom_mode >> 24) & 0xFF
    if main == PX4_MAIN_AUTO:
        return PX4_AUTO_SUB_MODES.get(sub, "auto")
    return PX4_MAIN_MODES.get(main, "unknown")


def heartbeat_mode_name(autopilot: int, base_mode: int, custom_mode: int) -> str:
    """The mode a HEARTBEAT reports: the PX4 name when the autopilot is PX4 and the
    custom-mode flag is set, "unknown" otherwise (other autopilots are not decoded)."""
    if autopilot != mavlink2.MAV_AUTOPILOT_PX4:
        return "unknown"
    if not base_mode & mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return "unknown"
    return px4_mode_name(custom_mode)


# --------------------------------------------------------------------------- builders (pure)


@dataclass(frozen=True)
class Target:
    """The MAVLink address of a vehicle's autopilot: system id and component id."""

    system: int
    component: int = AUTOPILOT_COMPONENT_ID


def command_name(command: int) -> str:
    """ "MAV_CMD_NAV_TAKEOFF" for 22, or "command 12345" if unknown."""
    entry = mavlink2.enums["MAV_CMD"].get(command)
    return str(entry.name) if entry is not None else f"command {command}"


def result_name(result: int) -> str:
    """ "MAV_RESULT_DENIED" for 2, or "result 99" if unknown."""
    entry = mavlink2.enums["MAV_RESULT"].get(result)
    return str(entry.name) if entry is not None else f"result {result}"


def gcs_heartbeat() -> Any:
    """HEARTBEAT of a ground station (MAV_TYPE_GCS, no autopilot, active); send at 1 Hz."""
    return mavlink2.MAVLink_heartbeat_message(
        mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, mavlink2.MAV_STATE_ACTIVE, 3
    )


def command_long(
    target: Target, command: int, params: Sequence[float] = (), confirmation: int = 0
) -> Any:
    """COMMAND_LONG `command` with up to 7 parameters (missing ones are 0)."""
    p = [float(x) for x in params]
    if len(p) > 7:
        raise ValueError(f"COMMAND_LONG takes 7 parameters, got {len(p)}")
    p += [0.0] * (7 - len(p))
    return mavlink2.MAVLink_command_long_message(
        target.system, target.component, command, confirmation, *p
    )


def arm_command(target: Target, arm: bool = True) -> Any:
    """MAV_CMD_COMPONENT_ARM_DISARM: param1 = 1 to arm, 0 to disarm."""
    return command_long(target, mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, (1.0 if arm else 0.0,))


def takeoff_command(target: Target, altitude_amsl_m: float = math.nan) -> Any:
    """MAV_CMD_NAV_TAKEOFF from the current position: param7 = altitude AMSL, m (NaN: the
    vehicle's own takeoff altitude, MIS_TAKEOFF_ALT); yaw (param4), latitude and longitude
    (param5, 6) are NaN, i.e. keep heading and take off where the vehicle is."""
    nan = math.nan
    return command_long(
        target, mavlink2.MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, nan, nan, nan, altitude_amsl_m)
    )


def land_command(target: Target) -> Any:
    """MAV_CMD_NAV_LAND where the vehicle is (yaw, latitude, longitude, altitude NaN)."""
    nan = math.nan
    return command_long(target, mavlink2.MAV_CMD_NAV_LAND, (0.0, 0.0, 0.0, nan, nan, nan, nan))


def set_mode_command(target: Target, main_mode: int, sub_mode: int = 0) -> Any:
    """MAV_CMD_DO_SET_MODE to a PX4 custom mode: param1 = MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
    param2 = main mode, param3 = sub-mode."""
    return command_long(
        target,
        mavlink2.MAV_CMD_DO_SET_MODE,
        (float(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(main_mode), float(sub_mode)),
    )


def offboard_mode_command(target: Target) -> Any:
    """DO_SET_MODE to PX4 OFFBOARD (main mode 6)."""
    return set_mode_command(target, PX4_MAIN_OFFBOARD)


def hold_mode_command(target: Target) -> Any:
    """DO_SET_MODE to PX4 HOLD (AUTO.LOITER: main mode 4, sub-mode 3)."""
    return set_mode_command(target, PX4_MAIN_AUTO, PX4_SUB_HOLD)


def message_interval_command(target: Target, message_id: int, interval_s: float | None) -> Any:
    """MAV_CMD_SET_MESSAGE_INTERVAL: stream `message_id` every `interval_s` s; None stops it
    (interval -1), 0 restores the vehicle's default rate."""
    interval_us = -1.0 if interval_s is None else interval_s * 1e6
    return command_long(
        target, mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, (float(message_id), interval_us)
    )


_MASK_ACCEL: Final = (
    mavlink2.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AZ_IGNORE
)
_MASK_VELOCITY: Final = (
    mavlink2.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_VZ_IGNORE
)
_MASK_YAW: Final = mavlink2.POSITION_TARGET_TYPEMASK_YAW_IGNORE
_MASK_YAW_RATE: Final = mavlink2.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE


def position_type_mask(*, velocity: bool, yaw: bool) -> int:
    """SET_POSITION_TARGET type_mask using x, y, z, optionally vx, vy, vz (feed-forward) and yaw.

    Acceleration and yaw rate are always ignored. Position only: 0xDF8; position + yaw: 0x9F8
    (MAVSDK's `set_position_ned`); position + velocity: 0xDC0; all three: 0x9C0.
    """
    mask = int(_MASK_ACCEL | _MASK_YAW_RATE)
    if not velocity:
        mask |= _MASK_VELOCITY
    if not yaw:
        mask |= _MASK_YAW
    return mask


def position_target_local_ned(
    target: Target,
    position_ned_m: FloatArray | Sequence[float],
    velocity_ned_mps: FloatArray | Sequence[float] | None = None,
    yaw_rad: float | None = None,
    time_boot_ms: int = 0,
) -> Any:
    """SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_LOCAL_NED.

    Args:
        target: The vehicle.
        position_ned_m: (3,) north, east, down, m.
        velocity_ned_mps: (3,) velocity feed-forward, m/s; None: position only.
        yaw_rad: Heading, rad (0 = north); None: ignored (the vehicle keeps its heading).
        time_boot_ms: Our time since boot, ms (informational for the vehicle).
    """
    p = np.asarray(position_ned_m, dtype=float)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"position_ned_m must be 3 finite numbers, got {p!r}")
    v = np.zeros(3) if velocity_ned_mps is None else np.asarray(velocity_ned_mps, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ValueError(f"velocity_ned_mps must be 3 finite numbers, got {v!r}")
    if yaw_rad is not None and not math.isfinite(yaw_rad):
        raise ValueError(f"yaw_rad must be finite or None, got {yaw_rad!r}")
    mask = position_type_mask(velocity=velocity_ned_mps is not None, yaw=yaw_rad is not None)
    return mavlink2.MAVLink_set_position_target_local_ned_message(
        int(time_boot_ms) & 0xFFFFFFFF,
        target.system,
        target.component,
        mavlink2.MAV_FRAME_LOCAL_NED,
        mask,
        float(p[0]),
        float(p[1]),
        float(p[2]),
        float(v[0]),
        float(v[1]),
        float(v[2]),
        0.0,
        0.0,
        0.0,
        0.0 if yaw_rad is None else float(yaw_rad),
        0.0,
    )


# --------------------------------------------------------------------------- signing

SIGNING_EPOCH_UNIX_S: Final = 1_420_070_400
"""MAVLink signature timestamps count 10 us units from 2015-01-01 00:00 UTC."""
SIGNATURE_LEN: Final = 13
"""link id (1) + timestamp (6) + signature (6) bytes at the end of a signed packet."""
SignatureRejection = Literal["unsigned", "bad_signature", "replayed"]


def signing_timestamp(unix_s: float | None = None) -> int:
    """A MAVLink signature timestamp: 10 us units since 2015-01-01 (now by default)."""
    t = time.time() if unix_s is None else unix_s
    return int(max(0.0, t - SIGNING_EPOCH_UNIX_S) * 100_000)


def signature_matches(packet: bytes, secret: bytes) -> bool:
    """True when the last 6 bytes of a signed MAVLink 2 packet are SHA-256(secret + the rest)[:6]
    (whatever its timestamp)."""
    if len(packet) < SIGNATURE_LEN + 12:
        return False
    return hashlib.sha256(secret + packet[:-6]).digest()[:6] == packet[-6:]


def signature_rejection(packet: bytes, secret: bytes) -> SignatureRejection:
    """Why pymavlink's signature check refused `packet`: "unsigned" (MAVLink 1, or MAVLink 2
    without the signed flag), "replayed" (signed with our key but its timestamp is not newer
    than the last one of its stream, or over a minute older than ours: a replay) or
    "bad_signature" (signed with another key, or altered)."""
    signed = len(packet) >= 3 and packet[0] == mavlink2.PROTOCOL_MARKER_V2 and packet[2] & 1
    if not signed:
        return "unsigned"
    return "replayed" if signature_matches(packet, secret) else "bad_signature"


def packet_origin(packet: bytes) -> str:
    """ "message 76 from system 255/190" from a packet's header (for logs), "?" if too short."""
    try:
        if packet[0] == mavlink2.PROTOCOL_MARKER_V2:
            sysid, compid, lo, mid, hi = struct.unpack_from("<BBBBB", packet, 5)
            return f"message {lo | (mid << 8) | (hi << 16)} from system {sysid}/{compid}"
        sysid, compid, msgid = struct.unpack_from("<BBB", packet, 3)
        return f"message {msgid} from system {sysid}/{compid}"
    except (IndexError, struct.error):
        return "?"


def _reject_unsigned(mav: Any, msg_id: int) -> bool:
    """pymavlink's allow_unsigned_callback: accept nothing unsigned."""
    return False


class _MAVLink(mavlink2.MAVLink):  # type: ignore[misc]  # pymavlink is untyped
    """pymavlink's MAVLink 2 object with one fix to the signature check.

    pymavlink's `check_signature` records a packet's timestamp as its stream's newest *before*
    it compares the signature, so one forged packet with a far-future timestamp would make every
    genuine packet of that stream look like a replay. Here the signature is compared first; only
    a correctly signed packet reaches pymavlink's timestamp check.
    """

    def check_signature(self, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        """True when `msgbuf` carries our signature and a fresh timestamp (pymavlink's check,
        reached only by correctly signed packets)."""
        if not signature_matches(bytes(msgbuf), self.signing.secret_key):
            return False
        return bool(super().check_signature(msgbuf, src_system, src_component))


def new_encoder(system_id: int = GCS_SYSTEM_ID, component_id: int = GCS_COMPONENT_ID) -> Any:
    """A pymavlink MAVLink 2 encoder/parser object for our side of a link (no file)."""
    mav = _MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    mav.robust_parsing = True
    return mav


def new_parser(encoder: Any) -> Any:
    """A fresh parser for the link of `encoder` (same MAVLink address), sharing its signing
    state: the key, the newest timestamp of every stream heard (replay protection survives the
    fresh parser) and our own timestamp."""
    parser = new_encoder(encoder.srcSystem, encoder.srcComponent)
    parser.signing = encoder.signing
    return parser


def enable_signing(encoder: Any, key: MavlinkSigningKey) -> None:
    """Sign everything `encoder` packs with `key`, and make it (and every `new_parser` of it)
    reject unsigned, badly signed and replayed packets (they come out as BAD_DATA with reason
    "Invalid signature"; `signature_rejection` tells which). Timestamps start at the wall
    clock and follow it (`refresh_signing_clock`)."""
    signing = encoder.signing
    signing.secret_key = key.secret
    signing.link_id = key.link_id
    signing.sign_outgoing = True
    signing.allow_unsigned_callback = _reject_unsigned
    signing.timestamp = max(int(signing.timestamp), signing_timestamp())


def signing_enabled(mav: Any) -> bool:
    """True when `mav` checks signatures (a key is set)."""
    return mav.signing.secret_key is not None


def refresh_signing_clock(mav: Any) -> None:
    """Move `mav`'s signing timestamp up to the wall clock (never back): our packets then carry
    the real time, so a restarted peer's fresh stream is not older than what we remember, and a
    stream new to us is judged against the real time."""
    signing = mav.signing
    if signing.secret_key is not None:
        signing.timestamp = max(int(signing.timestamp), signing_timestamp())


def signature_failure(msg: Any, mav: Any) -> SignatureRejection | None:
    """For a BAD_DATA message from parser `mav`: why its signature was refused, or None when
    it was refused for another reason."""
    if not signing_enabled(mav) or str(getattr(msg, "reason", "")) != "Invalid signature":
        return None
    return signature_rejection(bytes(msg.data), mav.signing.secret_key)


def pack(msg: Any, encoder: Any) -> bytes:
    """The wire bytes of `msg` from `encoder` (a `new_encoder()`), advancing its sequence
    (and signed, with the wall-clock timestamp, when `encoder` signs)."""
    refresh_signing_clock(encoder)
    data = bytes(msg.pack(encoder))
    encoder.seq = (encoder.seq + 1) % 256
    return data


# --------------------------------------------------------------------------- vehicle state


@dataclass(frozen=True)
class VehicleStatus:
    """What the link knows of its vehicle, at `time_s` on the link's clock.

    Attributes:
        time_s: When the snapshot was taken (link clock, s).
        system_id: The vehicle's MAVLink system id (None until heard).
        address: The vehicle's UDP (host, port) (None until heard).
        heartbeat_s: Link-clock time of the last HEARTBEAT, s (None: never).
        lost: No HEARTBEAT for `lost_after_s` (or never heard).
        mode: PX4 mode name (`px4_mode_name`), "unknown" before the first HEARTBEAT.
        custom_mode: Raw HEARTBEAT.custom_mode.
        armed: MAV_MODE_FLAG_SAFETY_ARMED in the last HEARTBEAT.
        landed_state: MAV_LANDED_STATE_* of the last EXTENDED_SYS_STATE (0: undefined).
        position_ned_m: (3,) local NED position, m (None until heard).
        velocity_ned_mps: (3,) local NED velocity, m/s (None until heard).
        position_s: Link-clock time the position was received, s (None until heard).
        yaw_rad: Heading from ATTITUDE, rad (None until heard).
        home_amsl_m: Altitude AMSL of home, m, from GLOBAL_POSITION_INT (alt - relative_alt).
    """

    time_s: float
    system_id: int | None
    address: Address | None
    heartbeat_s: float | None
    lost: bool
    mode: str
    custom_mode: int
    armed: bool
    landed_state: int
    position_ned_m: FloatArray | None
    velocity_ned_mps: FloatArray | None
    position_s: float | None
    yaw_rad: float | None
    home_amsl_m: float | None

    @property
    def landed(self) -> bool:
        """On the ground: landed state ON_GROUND, or (landed state unknown) disarmed."""
        if self.landed_state == mavlink2.MAV_LANDED_STATE_UNDEFINED:
            return not self.armed
        return bool(self.landed_state == mavlink2.MAV_LANDED_STATE_ON_GROUND)

    @property
    def airborne(self) -> bool:
        """Armed and not on the ground."""
        return self.armed and not self.landed

    @property
    def altitude_m(self) -> float | None:
        """Height above the local origin (-down), m, or None before the first position."""
        return None if self.position_ned_m is None else -float(self.position_ned_m[2])


@dataclass
class _PendingCommand:
    command: int
    future: asyncio.Future[int]
    progress_wall_s: float | None = None
    """Loop time of the last IN_PROGRESS answer."""


class MavlinkLink(asyncio.DatagramProtocol):
    """One vehicle's MAVLink link, bound to 127.0.0.1:`port` (see the module docstring).

    Args:
        port: Local UDP port the vehicle sends to (14540 + m for PX4 SITL vehicle m).
        system_id: The vehicle's system id (m + 1); None: the first system heard.
        vehicle_component: Component whose HEARTBEAT and state we follow (1: the autopilot).
        clock: Time source for heartbeat ages and sample times, s (default: monotonic wall).
        lost_after_s: The link is lost after this long without a HEARTBEAT (clock seconds)...
        lost_min_wall_s: ... and at least this long in wall seconds.
        own_system_id / own_component_id: Our MAVLink address (a GCS by default).
        signing: MAVLink 2 signing key: sign everything we send and drop (and count in
            `errors` as "unsigned", "bad_signature" or "replayed") every packet without a
            valid signature; None (default): no signing, unsigned and signed packets accepted.
        name: For log messages.

    Use `await link.open()` (or `async with`) on the event loop that will own the socket.
    """

    def __init__(
        self,
        port: int,
        *,
        system_id: int | None = None,
        vehicle_component: int = AUTOPILOT_COMPONENT_ID,
        clock: Callable[[], float] = time.monotonic,
        lost_after_s: float = 3.0,
        lost_min_wall_s: float = 2.0,
        own_system_id: int = GCS_SYSTEM_ID,
        own_component_id: int = GCS_COMPONENT_ID,
        signing: MavlinkSigningKey | None = None,
        name: str = "",
    ) -> None:
        if not 0 <= port <= 65535:
            raise ValueError(f"port must be a UDP port, got {port}")
        if not (math.isfinite(lost_after_s) and lost_after_s > 0):
            raise ValueError(f"lost_after_s must be finite and > 0, got {lost_after_s}")
        self.port = port
        self.name = name or f"mavlink:{port}"
        self.lost_after_s = float(lost_after_s)
        self.lost_min_wall_s = float(lost_min_wall_s)
        self._clock = clock
        self._expected_system = system_id
        self._vehicle_component = vehicle_component
        self._own_system = own_system_id
        self._encoder = new_encoder(own_system_id, own_component_id)
        if signing is not None:
            enable_signing(self._encoder, signing)
            log.info(
                "%s: MAVLink signing on (key %s from %s, link id %d)",
                self.name,
                signing.fingerprint,
                signing.source,
                signing.link_id,
            )
        self._parser = new_parser(self._encoder)
        self._transport: asyncio.DatagramTransport | None = None
        self._address: Address | None = None
        self._system_id: int | None = system_id

        self.errors: Counter[str] = Counter()
        """Bad input and handler failures, by reason."""
        self.ignored: Counter[str] = Counter()
        """Benign drops: other systems/components, message types without a handler."""
        self.received: Counter[str] = Counter()
        """Messages from the vehicle, by type (dispatched or not)."""
        self.sent: Counter[str] = Counter()
        """Messages sent, by type."""
        self.handlers: dict[str, list[Handler]] = {}
        """Handlers by message type; `on()` adds one."""
        self._noted: set[str] = set()

        self._heartbeat_s: float | None = None
        self._heartbeat_wall_s = 0.0
        self._custom_mode = 0
        self._mode = "unknown"
        self._armed = False
        self._landed_state = int(mavlink2.MAV_LANDED_STATE_UNDEFINED)
        self._position_ned: FloatArray | None = None
        self._velocity_ned: FloatArray | None = None
        self._position_s: float | None = None
        self._yaw_rad: float | None = None
        self._home_amsl_m: float | None = None
        self._pending: _PendingCommand | None = None
        self._command_lock = asyncio.Lock()
        self._changed = asyncio.Event()

        self.on("HEARTBEAT", self._on_heartbeat)
        self.on("LOCAL_POSITION_NED", self._on_local_position_ned)
        self.on("GLOBAL_POSITION_INT", self._on_global_position_int)
        self.on("EXTENDED_SYS_STATE", self._on_extended_sys_state)
        self.on("ATTITUDE", self._on_attitude)
        self.on("COMMAND_ACK", self._on_command_ack)
        self.on("STATUSTEXT", self._on_statustext)

    # -- lifecycle ---------------------------------------------------------------------------

    async def open(self) -> None:
        """Bind 127.0.0.1:`port` (OSError if it is taken)."""
        if self._transport is not None:
            return
        loop = asyncio.get_running_loop()
        await loop.create_datagram_endpoint(lambda: self, local_addr=(LOOPBACK, self.port))
        log.info("%s: listening on %s:%d", self.name, LOOPBACK, self.port)

    def close(self) -> None:
        """Close the socket; a pending command fails with LinkError (idempotent)."""
        if self._transport is not None:
            self._transport.close()
            self._transport = None
        pending = self._pending
        if pending is not None and not pending.future.done():
            pending.future.set_exception(
                LinkError(f"{self.name}: link closed during {command_name(pending.command)}")
            )

    async def __aenter__(self) -> MavlinkLink:
        await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    @property
    def is_open(self) -> bool:
        """True between open() and close()."""
        return self._transport is not None

    @property
    def local_address(self) -> Address:
        """The bound (host, port); RuntimeError before open()."""
        if self._transport is None:
            raise RuntimeError(f"{self.name}: not open")
        host, port = self._transport.get_extra_info("sockname")[:2]
        return (str(host), int(port))

    # -- asyncio.DatagramProtocol ------------------------------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.DatagramTransport, transport)

    def connection_lost(self, exc: Exception | None) -> None:
        self._transport = None

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable after a send while the vehicle is down: normal for UDP.
        log.debug("%s: %s", self.name, exc)

    def datagram_received(self, data: bytes, addr: Address) -> None:
        """Parse one datagram and dispatch its messages (UDP keeps packets whole)."""
        refresh_signing_clock(self._parser)
        try:
            msgs = self._parser.parse_buffer(data) or []
        except Exception as err:  # pymavlink raises on some malformed input even when robust
            self._count_error("parse_error", f"{err} from {addr}")
            self._parser = new_parser(self._encoder)
            return
        for msg in msgs:
            self.dispatch(msg, addr)
        if self._parser.buf_len() > 0:
            self._count_error("truncated", f"{self._parser.buf_len()} bytes left from {addr}")
            self._parser = new_parser(self._encoder)  # drop the partial packet

    # -- dispatch ----------------------------------------------------------------------------

    def on(self, message_type: str, handler: Handler) -> None:
        """Call `handler(msg)` for every `message_type` message of the vehicle (after those
        registered before)."""
        self.handlers.setdefault(message_type, []).append(handler)

    def dispatch(self, msg: Any, addr: Address) -> None:
        """Filter, count and hand one parsed message to its handlers."""
        mtype = str(msg.get_type())
        if mtype == "BAD_DATA":
            reason = str(getattr(msg, "reason", ""))
            refused = signature_failure(msg, self._parser)
            if refused is not None:
                self._count_error(refused, f"{packet_origin(bytes(msg.data))} from {addr}")
            elif "CRC" in reason:
                self._count_error("bad_crc", f"{reason} from {addr}")
            elif "prefix" in reason.lower():
                self._count_error("garbage", f"{len(msg.data)} bytes from {addr}")
            else:
                self._count_error("bad_data", f"{reason} from {addr}")
            return
        if mtype.startswith("UNKNOWN_"):
            self._count_error("unknown_message", f"message id {mtype[8:]} from {addr}")
            return
        src = int(msg.get_srcSystem())
        if src == self._own_system:
            self.ignored["own_system"] += 1
            return
        if self._system_id is None:
            self._system_id = src
            log.info("%s: vehicle is system %d", self.name, src)
        if src != self._system_id:
            self.ignored["other_system"] += 1
            return
        if getattr(msg, "target_system", 0) not in (0, self._own_system):
            self.ignored["for_other_system"] += 1
            return
        if self._address != addr and not self._learn_address(msg, mtype, addr):
            self._count_error("foreign_address", f"{mtype} as system {src} from {addr}")
            return
        self.received[mtype] += 1
        handlers = self.handlers.get(mtype)
        if not handlers:
            self.ignored[f"unhandled:{mtype}"] += 1
            if mtype not in self._noted:
                self._noted.add(mtype)
                log.info("%s: no handler for %s messages (ignored)", self.name, mtype)
            return
        for handler in handlers:
            try:
                handler(msg)
            except Exception:
                self.errors["handler_error"] += 1
                log.exception("%s: handler for %s failed", self.name, mtype)
        self._notify()

    def _learn_address(self, msg: Any, mtype: str, addr: Address) -> bool:
        """Whether a packet from `addr`, not the vehicle's known address, may be taken; if so the
        link now sends there. Like MAVSDK's udpin, the link learns where the vehicle is from
        what it hears, but only from a HEARTBEAT of the vehicle's own system and autopilot
        component, and only while no address is known or the vehicle has been lost (it
        restarted on another port). While the vehicle is heard, anything in its name from
        elsewhere is dropped: a sender on our port cannot take the link over."""
        if mtype != "HEARTBEAT" or int(msg.get_srcComponent()) != self._vehicle_component:
            return self._address is None  # state before the first heartbeat; no address yet
        if self._address is not None and not self.lost:
            return False
        log.info("%s: vehicle %d at %s:%d", self.name, int(msg.get_srcSystem()), *addr)
        self._address = addr
        return True

    def _count_error(self, reason: str, detail: str) -> None:
        self.errors[reason] += 1
        n = self.errors[reason]
        if n <= 5 or n % 100 == 0:
            log.warning("%s: %s (#%d): %s", self.name, reason, n, detail)

    def _notify(self) -> None:
        event, self._changed = self._changed, asyncio.Event()
        event.set()

    async def wait_change(self, timeout_s: float) -> bool:
        """Wait until the next message has been handled, at most `timeout_s` wall seconds;
        True if one was."""
        event = self._changed
        try:
            await asyncio.wait_for(event.wait(), timeout_s)
        except TimeoutError:
            return False
        return True

    async def wait_for(
        self, predicate: Callable[[VehicleStatus], bool], timeout_s: float, what: str
    ) -> VehicleStatus:
        """The first status satisfying `predicate`, checked after every message; LinkError
        naming `what` after `timeout_s` wall seconds."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout_s
        while True:
            status = self.status()
            if predicate(status):
                return status
            remaining = deadline - loop.time()
            if remaining <= 0:
                raise LinkError(f"{self.name}: timed out after {timeout_s:g} s waiting for {what}")
            await self.wait_change(min(remaining, 0.5))

    # -- handlers ----------------------------------------------------------------------------

    def _from_vehicle_component(self, msg: Any) -> bool:
        if int(msg.get_srcComponent()) == self._vehicle_component:
            return True
        self.ignored["other_component"] += 1
        return False

    def _on_heartbeat(self, msg: Any) -> None:
        if not self._from_vehicle_component(msg):
            return
        was_lost = self.lost
        self._heartbeat_s = self._clock()
        self._heartbeat_wall_s = time.monotonic()
        self._custom_mode = int(msg.custom_mode)
        base_mode = int(msg.base_mode)
        self._armed = bool(base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
        mode = heartbeat_mode_name(int(msg.autopilot), base_mode, self._custom_mode)
        if mode != self._mode:
            log.info("%s: mode %s -> %s", self.name, self._mode, mode)
            self._mode = mode
        if was_lost:
            log.info("%s: heartbeat from vehicle %s", self.name, self._system_id)

    def _on_local_position_ned(self, msg: Any) -> None:
        if not self._from_vehicle_component(msg):
            return
        p = np.array([msg.x, msg.y, msg.z], dtype=float)
        v = np.array([msg.vx, msg.vy, msg.vz], dtype=float)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            self._count_error("non_finite_position", f"{p} {v}")
            return
        self._position_ned, self._velocity_ned = p, v
        self._position_s = self._clock()

    def _on_global_position_int(self, msg: Any) -> None:
        if not self._from_vehicle_component(msg):
            return
        self._home_amsl_m = (int(msg.alt) - int(msg.relative_alt)) / 1000.0

    def _on_extended_sys_state(self, msg: Any) -> None:
        if not self._from_vehicle_component(msg):
            return
        self._landed_state = int(msg.landed_state)

    def _on_attitude(self, msg: Any) -> None:
        if not self._from_vehicle_component(msg):
            return
        yaw = float(msg.yaw)
        if math.isfinite(yaw):
            self._yaw_rad = yaw

    def _on_command_ack(self, msg: Any) -> None:
        pending = self._pending
        if pending is None or int(msg.command) != pending.command or pending.future.done():
            self.ignored["unexpected_ack"] += 1
            return
        result = int(msg.result)
        if result == mavlink2.MAV_RESULT_IN_PROGRESS:
            pending.progress_wall_s = pending.future.get_loop().time()
            return
        pending.future.set_result(result)

    def _on_statustext(self, msg: Any) -> None:
        text = msg.text
        if isinstance(text, bytes):
            text = text.split(b"\x00", 1)[0].decode("utf-8", errors="replace")
        log.info("%s: vehicle says (severity %d): %s", self.name, int(msg.severity), text)

    # -- state -------------------------------------------------------------------------------

    @property
    def lost(self) -> bool:
        """No HEARTBEAT for `lost_after_s` clock seconds and for `lost_min_wall_s` wall seconds
        (or never heard one). The wall-clock floor keeps a simulation run many times faster
        than real time from declaring a link lost over a few hundred milliseconds of CPU load."""
        hb = self._heartbeat_s
        if hb is None:
            return True
        return (
            self._clock() - hb > self.lost_after_s
            and time.monotonic() - self._heartbeat_wall_s > self.lost_min_wall_s
        )

    @property
    def signatures_ok(self) -> int:
        """Packets whose signature was checked and accepted (0 when signing is off)."""
        return int(self._encoder.signing.goodsig_count)

    @property
    def target(self) -> Target:
        """The vehicle's MAVLink address (LinkError before its system id is known)."""
        if self._system_id is None:
            raise LinkError(f"{self.name}: vehicle not heard yet")
        return Target(self._system_id, self._vehicle_component)

    @property
    def vehicle_address(self) -> Address | None:
        """The vehicle's UDP address, learnt from its packets (None until heard)."""
        return self._address

    def status(self) -> VehicleStatus:
        """A snapshot of the vehicle state (see `VehicleStatus`)."""
        p, v = self._position_ned, self._velocity_ned
        return VehicleStatus(
            time_s=self._clock(),
            system_id=self._system_id,
            address=self._address,
            heartbeat_s=self._heartbeat_s,
            lost=self.lost,
            mode=self._mode,
            custom_mode=self._custom_mode,
            armed=self._armed,
            landed_state=self._landed_state,
            position_ned_m=None if p is None else p.copy(),
            velocity_ned_mps=None if v is None else v.copy(),
            position_s=self._position_s,
            yaw_rad=self._yaw_rad,
            home_amsl_m=self._home_amsl_m,
        )

    # -- sending -----------------------------------------------------------------------------

    def send(self, msg: Any) -> bool:
        """Send one message to the vehicle; False (nothing sent) before its address is known
        or when the link is closed."""
        if self._transport is None or self._transport.is_closing() or self._address is None:
            return False
        self._transport.sendto(pack(msg, self._encoder), self._address)
        self.sent[str(msg.get_type())] += 1
        return True

    async def command(self, msg: Any, *, timeout_s: float = 1.0, attempts: int = 3) -> None:
        """Send a COMMAND_LONG and wait for ACCEPTED.

        Each attempt waits `timeout_s` wall seconds for the matching COMMAND_ACK (an
        IN_PROGRESS answer restarts the wait without resending); a retry bumps `confirmation`. Commands are sent
        one at a time. Raises LinkError naming the command and the result when the vehicle
        answers anything but ACCEPTED, or when no answer came after `attempts` attempts.
        """
        if msg.get_type() != "COMMAND_LONG":
            raise ValueError(f"command() takes COMMAND_LONG, got {msg.get_type()}")
        cmd = int(msg.command)
        name = command_name(cmd)
        async with self._command_lock:
            loop = asyncio.get_running_loop()
            for attempt in range(max(1, attempts)):
                pending = _PendingCommand(cmd, loop.create_future())
                self._pending = pending
                msg.confirmation = attempt
                try:
                    if not self.send(msg):
                        raise LinkError(f"{self.name}: {name}: no link to the vehicle")
                    wait_s = timeout_s
                    while True:
                        try:
                            result = await asyncio.wait_for(asyncio.shield(pending.future), wait_s)
                        except TimeoutError:
                            progress = pending.progress_wall_s
                            if progress is None or loop.time() - progress >= timeout_s:
                                break  # no answer: resend
                            wait_s = timeout_s - (loop.time() - progress)  # IN_PROGRESS
                            continue
                        if result == mavlink2.MAV_RESULT_ACCEPTED:
                            log.info("%s: %s accepted", self.name, name)
                            return
                        raise LinkError(f"{self.name}: {name} refused: {result_name(result)}")
                finally:
                    self._pending = None
                log.warning("%s: no COMMAND_ACK for %s (attempt %d)", self.name, name, attempt + 1)
        raise LinkError(
            f"{self.name}: {name}: no COMMAND_ACK after {max(1, attempts)} attempts "
            f"of {timeout_s:g} s (result: timeout)"
        )
