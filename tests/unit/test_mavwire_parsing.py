"""The one datagram parser (isac_mission/mavwire/parsing.py) that the service's link and the
simulated vehicle share: every refusal has its reason, and nothing carries over between
datagrams."""

from __future__ import annotations

import struct
from typing import Any

from isac_mission.config import MavlinkSigningKey
from isac_mission.mavwire.builders import gcs_heartbeat
from isac_mission.mavwire.dialect import mavlink2
from isac_mission.mavwire.parsing import REJECT_REASONS, DatagramParser, Rejection, packet_origin
from isac_mission.mavwire.signing import enable_signing, new_encoder, pack

ADDR = ("127.0.0.1", 40000)
KEY = MavlinkSigningKey(bytes(range(1, 33)), link_id=2, source="test")
WRONG = MavlinkSigningKey(bytes(range(3, 35)), link_id=2, source="test")


def heartbeat_bytes(key: MavlinkSigningKey | None = None, system: int = 255) -> bytes:
    enc = new_encoder(system, 190)
    if key is not None:
        enable_signing(enc, key)
    return pack(gcs_heartbeat(), enc)


def parser(key: MavlinkSigningKey | None = None) -> DatagramParser:
    enc = new_encoder(1, 1)
    if key is not None:
        enable_signing(enc, key)
    return DatagramParser(enc)


def reasons(items: list[Any]) -> list[str]:
    return [i.reason if isinstance(i, Rejection) else str(i.get_type()) for i in items]


def unknown_id_bytes() -> bytes:
    """A valid MAVLink 2 frame of message id 0xABCDE, outside the common dialect."""
    payload = b"\x01\x02"
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, 255, 190, 0xBCDE, 0x0A)
    crc = mavlink2.x25crc(header[1:] + payload).crc
    return header + payload + struct.pack("<H", crc)


def test_a_good_datagram_gives_its_messages_in_order() -> None:
    p = parser()
    two = heartbeat_bytes() + heartbeat_bytes(system=7)
    items = p.parse(two, ADDR)
    assert reasons(items) == ["HEARTBEAT", "HEARTBEAT"]
    assert [m.get_srcSystem() for m in items] == [255, 7]


def test_each_kind_of_bad_bytes_has_its_reason() -> None:
    p = parser()
    good = heartbeat_bytes()
    corrupt = bytearray(good)
    corrupt[-1] ^= 0xFF
    assert reasons(p.parse(b"\x00\x01garbage", ADDR)) == ["garbage"]
    assert reasons(p.parse(bytes(corrupt), ADDR)) == ["bad_crc"]
    assert reasons(p.parse(good[:7], ADDR)) == ["truncated"]
    assert reasons(p.parse(unknown_id_bytes(), ADDR)) == ["unknown_message"]
    assert reasons(p.parse(b"junk" + good, ADDR)) == ["garbage", "HEARTBEAT"]


def test_nothing_carries_over_from_a_truncated_datagram() -> None:
    p = parser()
    good = heartbeat_bytes()
    assert reasons(p.parse(good[:9], ADDR)) == ["truncated"]
    assert reasons(p.parse(good[9:], ADDR)) == ["garbage"]  # the rest alone is no packet
    assert reasons(p.parse(good, ADDR)) == ["HEARTBEAT"]


def test_signature_refusals_are_told_apart() -> None:
    p = parser(KEY)
    assert reasons(p.parse(heartbeat_bytes(None), ADDR)) == ["unsigned"]
    assert reasons(p.parse(heartbeat_bytes(WRONG), ADDR)) == ["bad_signature"]
    signed = heartbeat_bytes(KEY)
    assert reasons(p.parse(signed, ADDR)) == ["HEARTBEAT"]
    assert reasons(p.parse(signed, ADDR)) == ["replayed"]


def test_rejections_name_their_origin_and_use_the_known_reasons() -> None:
    p = parser(KEY)
    (rejection,) = p.parse(heartbeat_bytes(None), ADDR)
    assert isinstance(rejection, Rejection)
    assert rejection.reason in REJECT_REASONS
    assert rejection.detail == f"message 0 from system 255/190 from {ADDR}"
    assert packet_origin(b"") == "?"
