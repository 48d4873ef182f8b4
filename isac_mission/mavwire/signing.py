"""MAVLink 2 signing, and the pymavlink encoder/parser objects that sign and check.

Signing (`enable_signing` with a `MavlinkSigningKey`, from the scenario's
`security.mavlink_signing`): every message packed by the encoder is signed, with timestamps that
follow the wall clock; every packet without a valid signature comes out of a parser as BAD_DATA
("Invalid signature"), which `signature_failure` tells apart as `unsigned` (no signature, or
MAVLink 1), `bad_signature` (another key, or altered) or `replayed` (our key, but a timestamp not
newer than its stream's last). pymavlink does the checks; `_MAVLink` fixes their order so a forged
packet cannot poison a stream's timestamp. Off by default: nothing is signed and everything is
accepted, as MAVSDK and PX4 SITL expect.

Timestamps count 10 us units from 2015-01-01 00:00 UTC.
"""

from __future__ import annotations

import hashlib
import time
from typing import Any, Final, Literal, get_args

from isac_mission.config import MavlinkSigningKey
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.ports import GCS_COMPONENT_ID, GCS_SYSTEM_ID

SIGNING_EPOCH_UNIX_S: Final = 1_420_070_400
"""MAVLink signature timestamps count 10 us units from 2015-01-01 00:00 UTC."""
SIGNATURE_LEN: Final = 13
"""link id (1) + timestamp (6) + signature (6) bytes at the end of a signed packet."""
SignatureRejection = Literal["unsigned", "bad_signature", "replayed"]
SIGNATURE_REJECTIONS: Final[tuple[SignatureRejection, ...]] = get_args(SignatureRejection)
"""Every reason a signed link drops a packet for (the links count them under these names)."""


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
