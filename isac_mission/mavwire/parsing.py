"""One datagram parser for both ends of a MAVLink link, with the reasons it refuses bytes.

UDP keeps packets whole, so each datagram is parsed on its own (`DatagramParser`, with a pymavlink
parser from `signing.new_parser`, sharing the link's signing state: key, newest timestamp of every
stream): nothing carries over, and a truncated or corrupt packet cannot swallow the next datagram.
`DatagramParser.parse` returns, in order, every message of the datagram and a `Rejection` for
everything refused, with its reason:

- `garbage`: bytes that are not MAVLink (no packet start);
- `bad_crc`: a packet whose checksum is wrong;
- `bad_data`: another pymavlink complaint (bad length, bad flags, ...);
- `unsigned`, `bad_signature`, `replayed`: refused by the signature check (`signing`);
- `unknown_message`: a message id outside the common dialect;
- `parse_error`: pymavlink raised (then nothing of the datagram is kept);
- `truncated`: the datagram ended inside a packet.

The service's `MavlinkLink` and the simulated vehicle's links count these per reason.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any, Literal, get_args

from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.ports import Address
from isac_mission.mavwire.signing import new_parser, refresh_signing_clock, signature_failure

RejectReason = Literal[
    "garbage",
    "bad_crc",
    "bad_data",
    "unsigned",
    "bad_signature",
    "replayed",
    "unknown_message",
    "parse_error",
    "truncated",
]
REJECT_REASONS: tuple[RejectReason, ...] = get_args(RejectReason)
"""Every reason `DatagramParser.parse` gives."""


@dataclass(frozen=True)
class Rejection:
    """Bytes of a datagram refused before any handler saw them.

    Attributes:
        reason: Why (see the module docstring).
        detail: What and from where, for the log.
    """

    reason: RejectReason
    detail: str


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


def rejection_of(msg: Any, parser: Any, addr: Address) -> Rejection | None:
    """Why a message that `parser` produced is refused (BAD_DATA or an unknown message id),
    or None for a message of the dialect."""
    mtype = str(msg.get_type())
    if mtype == "BAD_DATA":
        reason = str(getattr(msg, "reason", ""))
        refused = signature_failure(msg, parser)
        if refused is not None:
            return Rejection(refused, f"{packet_origin(bytes(msg.data))} from {addr}")
        if "CRC" in reason:
            return Rejection("bad_crc", f"{reason} from {addr}")
        if "prefix" in reason.lower():
            return Rejection("garbage", f"{len(msg.data)} bytes from {addr}")
        return Rejection("bad_data", f"{reason} from {addr}")
    if mtype.startswith("UNKNOWN_"):
        return Rejection("unknown_message", f"message id {mtype[8:]} from {addr}")
    return None


class DatagramParser:
    """The datagram parser of one link (its encoder's MAVLink address and signing state).

    One pymavlink parser is kept while datagrams parse cleanly and replaced by a fresh one after
    a parse error or a datagram that ended inside a packet, so nothing carries over from one
    datagram to the next: the same as a fresh parser per datagram, without building one each time.
    """

    def __init__(self, encoder: Any) -> None:
        self._encoder = encoder
        self._parser = new_parser(encoder)

    def parse(self, data: bytes, addr: Address) -> list[Any]:
        """The messages of one datagram from `addr`, in order, each either a pymavlink message
        of the dialect or a `Rejection` (check with `isinstance(item, Rejection)`)."""
        parser = self._parser
        refresh_signing_clock(parser)
        try:
            msgs = parser.parse_buffer(data) or []
        except Exception as err:  # pymavlink raises on some malformed input even when robust
            self._parser = new_parser(self._encoder)
            return [Rejection("parse_error", f"{err} from {addr}")]
        items: list[Any] = []
        for msg in msgs:
            rejection = rejection_of(msg, parser, addr)
            items.append(msg if rejection is None else rejection)
        if parser.buf_len() > 0:
            items.append(Rejection("truncated", f"{parser.buf_len()} bytes left over from {addr}"))
            self._parser = new_parser(self._encoder)  # drop the partial packet
        return items
