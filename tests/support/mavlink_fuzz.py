"""MAVLink 2 fuzz input for the wire tests: hypothesis strategies and a raw frame builder.

`mavlink_frames()` draws one MAVLink 2 packet with a *valid* CRC (crc_extra included) of a random
message of the common dialect, from a random system and component, with random field values:
floats include NaN, infinities and absurd magnitudes, integers span their wire type, char
arrays are arbitrary bytes. A few fields that steer a vehicle (command, target_system,
coordinate_frame, type_mask, base_mode, custom_mode) are drawn half the time from the values
a PX4-like vehicle acts on, so the fuzz reaches the handlers rather than their first check.
`random_datagrams()` draws what a broken or hostile sender puts on a UDP port: random bytes,
packets with a corrupted CRC, truncated packets, several packets in one datagram.

Frames are built by hand (header, payload, X.25 CRC with crc_extra) rather than by pymavlink's
encoder, which refuses out-of-range values and always trims payloads.
"""

from __future__ import annotations

import os
import re
import struct
from typing import Any, Final

from hypothesis import strategies as st

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from isac_mission.mavwire.dialect import mavlink2

MESSAGE_IDS: Final = sorted(mavlink2.mavlink_map)
"""Every message id of the common dialect."""
STEERING_IDS: Final = [
    mavlink2.MAVLINK_MSG_ID_HEARTBEAT,
    mavlink2.MAVLINK_MSG_ID_COMMAND_LONG,
    mavlink2.MAVLINK_MSG_ID_COMMAND_INT,
    mavlink2.MAVLINK_MSG_ID_SET_MODE,
    mavlink2.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED,
    mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    mavlink2.MAVLINK_MSG_ID_EXTENDED_SYS_STATE,
    mavlink2.MAVLINK_MSG_ID_ATTITUDE,
    mavlink2.MAVLINK_MSG_ID_COMMAND_ACK,
    mavlink2.MAVLINK_MSG_ID_STATUSTEXT,
    mavlink2.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
    mavlink2.MAVLINK_MSG_ID_PARAM_SET,
    mavlink2.MAVLINK_MSG_ID_PING,
    mavlink2.MAVLINK_MSG_ID_MISSION_COUNT,
    mavlink2.MAVLINK_MSG_ID_MISSION_REQUEST_INT,
]
"""Messages a vehicle or a ground link handles: drawn more often than the rest."""
UNKNOWN_MESSAGE_ID: Final = 0xABCDE
"""A message id outside the common dialect (used as a barrier: counted as unknown)."""

_INT_RANGES: Final = {
    "B": (0, 2**8 - 1),
    "b": (-(2**7), 2**7 - 1),
    "H": (0, 2**16 - 1),
    "h": (-(2**15), 2**15 - 1),
    "I": (0, 2**32 - 1),
    "i": (-(2**31), 2**31 - 1),
    "Q": (0, 2**64 - 1),
    "q": (-(2**63), 2**63 - 1),
}
_STEERING_VALUES: Final[dict[str, list[int]]] = {
    "command": [
        mavlink2.MAV_CMD_COMPONENT_ARM_DISARM,
        mavlink2.MAV_CMD_NAV_TAKEOFF,
        mavlink2.MAV_CMD_NAV_LAND,
        mavlink2.MAV_CMD_DO_SET_MODE,
        mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL,
        mavlink2.MAV_CMD_REQUEST_MESSAGE,
        mavlink2.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
        mavlink2.MAV_CMD_GET_HOME_POSITION,
    ],
    "target_system": [0, 1, 2, 255],
    "target_component": [0, 1, 190],
    "coordinate_frame": [mavlink2.MAV_FRAME_LOCAL_NED],
    "type_mask": [0x9F8, 0xDF8, 0xDC7, 0xDC0, 0],
    "base_mode": [mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 0x81, 0xC1],
    "custom_mode": [0x00060000, 0x03040000, 0x06040000, 0x02040000],
    "autopilot": [mavlink2.MAV_AUTOPILOT_PX4],
}
_FLOAT32: Final = st.one_of(
    st.floats(width=32, allow_nan=True, allow_infinity=True),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), 3.4e38, -3.4e38, 0.0, -0.0]),
)
_FLOAT64: Final = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([float("nan"), float("inf"), 1e308, -1e308]),
)


def _format_codes(msgid: int) -> list[tuple[int, str]]:
    """(count, struct code) per wire field of message `msgid` (count 0: a scalar)."""
    fmt = mavlink2.mavlink_map[msgid].unpacker.format.lstrip("<")
    return [(int(n) if n else 0, c) for n, c in re.findall(r"(\d*)([a-zA-Z])", fmt)]


def _scalar(code: str) -> st.SearchStrategy[Any]:
    if code == "f":
        return _FLOAT32
    if code == "d":
        return _FLOAT64
    lo, hi = _INT_RANGES[code]
    return st.integers(lo, hi)


def frame(msgid: int, payload: bytes, *, sysid: int, compid: int, seq: int = 0) -> bytes:
    """A MAVLink 2 packet (unsigned) with a valid CRC: the dialect's crc_extra for a known
    message id, none for an unknown one."""
    header = struct.pack(
        "<BBBBBBBHB",
        0xFD,
        len(payload),
        0,
        0,
        seq & 0xFF,
        sysid,
        compid,
        msgid & 0xFFFF,
        msgid >> 16,
    )
    crc = mavlink2.x25crc(header[1:] + payload)
    cls = mavlink2.mavlink_map.get(msgid)
    if cls is not None:
        crc.accumulate(struct.pack("B", cls.crc_extra))
    return header + payload + struct.pack("<H", crc.crc)


def unknown_message(seq: int = 0, sysid: int = 250) -> bytes:
    """A well-formed packet of a message id outside the dialect: every receiver counts it as
    "unknown_message" and does nothing else (the barrier of the fuzz tests)."""
    return frame(UNKNOWN_MESSAGE_ID, b"\x01\x02\x03\x04", sysid=sysid, compid=190, seq=seq)


@st.composite
def mavlink_frames(
    draw: st.DrawFn, sysids: st.SearchStrategy[int] | None = None, steer: bool = True
) -> bytes:
    """One valid-CRC MAVLink 2 packet of a random common message with random field values.

    With `steer`, three packets in four are of a message in STEERING_IDS and their steering
    fields take, half the time, a value the vehicle acts on. Scalars and short float arrays are
    drawn value by value; long arrays and char arrays are random bytes (fast to draw)."""
    steering = steer and draw(st.integers(0, 3)) > 0
    msgid = draw(st.sampled_from(STEERING_IDS if steering else MESSAGE_IDS))
    cls = mavlink2.mavlink_map[msgid]
    parts: list[bytes] = []
    for name, (count, code) in zip(cls.ordered_fieldnames, _format_codes(msgid), strict=True):
        if code == "s":
            parts.append(draw(st.binary(max_size=count)).ljust(count, b"\x00"))
        elif count > 8 or (count and code not in "fd"):
            size = struct.calcsize(f"<{count}{code}")
            parts.append(draw(st.binary(min_size=size, max_size=size)))
        elif count:
            values = draw(st.lists(_scalar(code), min_size=count, max_size=count))
            parts.append(struct.pack(f"<{count}{code}", *values))
        elif steering and name in _STEERING_VALUES and draw(st.booleans()):
            parts.append(struct.pack(f"<{code}", draw(st.sampled_from(_STEERING_VALUES[name]))))
        else:
            parts.append(struct.pack(f"<{code}", draw(_scalar(code))))
    payload = b"".join(parts)
    if draw(st.booleans()):  # MAVLink 2 senders trim trailing zeros (at least one byte stays)
        payload = payload.rstrip(b"\x00") or b"\x00"
    sysid = draw(sysids if sysids is not None else st.integers(0, 255))
    compid = draw(st.one_of(st.just(1), st.integers(0, 255)))
    return frame(msgid, payload, sysid=sysid, compid=compid, seq=draw(st.integers(0, 255)))


@st.composite
def random_datagrams(draw: st.DrawFn) -> bytes:
    """Bytes that are not a well-formed packet: random, corrupted CRC, truncated, or a valid
    packet buried in junk."""
    kind = draw(st.sampled_from(["random", "bad_crc", "truncated", "junk_around"]))
    if kind == "random":
        return draw(st.binary(min_size=1, max_size=300))
    packet = draw(mavlink_frames())
    if kind == "bad_crc":
        i = draw(st.integers(len(packet) - 2, len(packet) - 1))
        flip = draw(st.integers(1, 255))
        return packet[:i] + bytes([packet[i] ^ flip]) + packet[i + 1 :]
    if kind == "truncated":
        return packet[: draw(st.integers(1, len(packet) - 1))]
    junk = draw(
        st.binary(min_size=1, max_size=40).filter(lambda b: 0xFD not in b and 0xFE not in b)
    )
    return junk + packet
