"""MAVLink 2 signing in isac_mission/mavwire/ (signing, parsing), without sockets:
what is signed, what is refused and why, and that a forged packet cannot poison a stream."""

from __future__ import annotations

import time

import pytest

from isac_mission.config import MavlinkSigningKey
from isac_mission.mavwire.builders import gcs_heartbeat
from isac_mission.mavwire.signing import (
    SIGNING_EPOCH_UNIX_S,
    enable_signing,
    new_encoder,
    new_parser,
    pack,
    signature_failure,
    signing_timestamp,
)

KEY = MavlinkSigningKey(bytes(range(1, 33)), link_id=3, source="test")
WRONG = MavlinkSigningKey(bytes(range(2, 34)), link_id=3, source="test")  # same stream as KEY


def signer(key: MavlinkSigningKey | None, system: int = 255) -> object:
    enc = new_encoder(system, 190)
    if key is not None:
        enable_signing(enc, key)
    return enc


def receiver(key: MavlinkSigningKey | None) -> object:
    enc = new_encoder(1, 1)
    if key is not None:
        enable_signing(enc, key)
    return new_parser(enc)


def parse_one(parser: object, data: bytes) -> tuple[str, str | None]:
    """(message type, signature failure or None) of a one-packet datagram."""
    msgs = parser.parse_buffer(data)  # type: ignore[attr-defined]
    assert msgs is not None and len(msgs) == 1
    msg = msgs[0]
    return str(msg.get_type()), signature_failure(msg, parser)


def packet_timestamp(data: bytes) -> int:
    return int.from_bytes(data[-12:-6], "little")


def test_timestamps_count_10_us_units_from_2015() -> None:
    assert signing_timestamp(SIGNING_EPOCH_UNIX_S) == 0
    assert signing_timestamp(SIGNING_EPOCH_UNIX_S + 1.5) == 150_000


def test_signed_packets_carry_link_id_and_a_wall_clock_timestamp() -> None:
    enc = signer(KEY)
    enc.signing.timestamp = 0  # type: ignore[attr-defined]
    before = signing_timestamp()
    data = pack(gcs_heartbeat(), enc)
    after = signing_timestamp(time.time())
    assert data[2] & 1, "signed flag"
    assert data[-13] == KEY.link_id
    assert before <= packet_timestamp(data) <= after + 1
    assert packet_timestamp(pack(gcs_heartbeat(), enc)) > packet_timestamp(data)


def test_only_correctly_signed_fresh_packets_pass() -> None:
    rx = receiver(KEY)
    good = pack(gcs_heartbeat(), signer(KEY))
    assert parse_one(rx, good) == ("HEARTBEAT", None)
    assert parse_one(rx, good) == ("BAD_DATA", "replayed")
    assert parse_one(rx, pack(gcs_heartbeat(), signer(WRONG))) == ("BAD_DATA", "bad_signature")
    assert parse_one(rx, pack(gcs_heartbeat(), signer(None))) == ("BAD_DATA", "unsigned")
    v1 = gcs_heartbeat().pack(signer(None), force_mavlink1=True)
    assert parse_one(rx, v1) == ("BAD_DATA", "unsigned")
    tampered = bytearray(pack(gcs_heartbeat(), signer(KEY, system=200)))
    tampered[-1] ^= 0x01
    assert parse_one(rx, bytes(tampered)) == ("BAD_DATA", "bad_signature")


def test_a_forged_future_timestamp_does_not_lock_out_the_genuine_stream() -> None:
    rx = receiver(KEY)
    forger = signer(WRONG)
    forger.signing.timestamp = 2**47  # type: ignore[attr-defined]
    data = pack(gcs_heartbeat(), forger)
    assert packet_timestamp(data) == 2**47
    assert parse_one(rx, data) == ("BAD_DATA", "bad_signature")
    assert parse_one(rx, pack(gcs_heartbeat(), signer(KEY))) == ("HEARTBEAT", None)


def test_replay_protection_survives_a_fresh_parser() -> None:
    enc = new_encoder(1, 1)
    enable_signing(enc, KEY)
    good = pack(gcs_heartbeat(), signer(KEY))
    assert parse_one(new_parser(enc), good) == ("HEARTBEAT", None)
    assert parse_one(new_parser(enc), good) == ("BAD_DATA", "replayed")


@pytest.mark.parametrize("sender_key", [None, KEY])
def test_without_signing_everything_is_accepted(sender_key: MavlinkSigningKey | None) -> None:
    rx = receiver(None)
    data = pack(gcs_heartbeat(), signer(sender_key))
    assert parse_one(rx, data) == ("HEARTBEAT", None)
    assert bool(data[2] & 1) is (sender_key is not None)
