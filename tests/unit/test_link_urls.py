"""Link URLs and the serial packet framer (isac_mission/mavwire/serial_link.py), without a device."""

from __future__ import annotations

import pytest

from isac_mission.config import MavlinkSigningKey
from isac_mission.errors import ConfigError
from isac_mission.mavwire.builders import gcs_heartbeat
from isac_mission.mavwire.serial_link import (
    LinkUrl,
    PacketFramer,
    parse_link_url,
    parse_vehicle_links,
)
from isac_mission.mavwire.signing import enable_signing, new_encoder, pack
from isac_mission.service.bridge.settings import BridgeSettings


def _packets(n: int, signed: bool = False) -> list[bytes]:
    encoder = new_encoder(255, 190)
    if signed:
        enable_signing(encoder, MavlinkSigningKey(bytes.fromhex("ab" * 32), source="test"))
    return [pack(gcs_heartbeat(), encoder) for _ in range(n)]


def test_link_urls_name_udp_ports_on_loopback_and_serial_devices() -> None:
    assert parse_link_url("udpin:127.0.0.1:14540") == LinkUrl("udpin", port=14540)
    assert parse_link_url("serial:/dev/ttyUSB0:115200") == LinkUrl(
        "serial", device="/dev/ttyUSB0", baud=115200
    )
    assert parse_link_url("serial:/dev/pts/5") == LinkUrl("serial", device="/dev/pts/5", baud=57600)
    assert str(parse_link_url("serial:/dev/pts/5")) == "serial:/dev/pts/5:57600"


@pytest.mark.parametrize(
    ("url", "why"),
    [
        ("udpin:0.0.0.0:14540", "127.0.0.1 only"),
        ("udpin:127.0.0.1:70000", "port must be 1..65535"),
        ("serial:ttyUSB0", "serial:/path/to/device"),
        ("tcp:127.0.0.1:5760", "expected udpin:127.0.0.1:PORT or serial:DEVICE"),
    ],
)
def test_a_bad_link_url_is_refused_naming_it(url: str, why: str) -> None:
    with pytest.raises(ValueError, match=why) as err:
        parse_link_url(url)
    assert repr(url) in str(err.value)


def test_vehicle_links_are_checked_against_the_fleet() -> None:
    assert parse_vehicle_links(["1=serial:/dev/pts/3"], 3) == {1: "serial:/dev/pts/3"}
    for bad in (["3=serial:/dev/pts/3"], ["x=serial:/dev/a"], ["1=serial:/a", "1=serial:/b"]):
        with pytest.raises(ValueError, match="vehicle link"):
            parse_vehicle_links(bad, 3)


def test_bridge_settings_name_a_bad_link_and_default_to_udp() -> None:
    assert BridgeSettings(index=2).link_url == "udpin:127.0.0.1:14542"
    assert BridgeSettings(index=2, link="serial:/dev/pts/1").link_url == "serial:/dev/pts/1"
    with pytest.raises(ConfigError, match="BridgeSettings: link: link 'serial:x'"):
        BridgeSettings(link="serial:x")


@pytest.mark.parametrize("signed", [False, True])
def test_the_framer_cuts_a_stream_into_whole_packets_whatever_the_chunks(signed: bool) -> None:
    packets = _packets(4, signed)
    stream = b"".join(packets)
    for chunk in (1, 3, 7, len(stream)):
        framer = PacketFramer()
        out: list[bytes] = []
        for i in range(0, len(stream), chunk):
            out += framer.feed(stream[i : i + chunk])
        assert out == packets
        assert framer.pending == 0


def test_bytes_between_packets_come_out_as_one_chunk_of_their_own() -> None:
    first, second = _packets(2)
    framer = PacketFramer()
    assert framer.feed(b"\x00\x01noise" + first + b"\x02" + second[:5]) == [
        b"\x00\x01noise",
        first,
        b"\x02",
    ]
    assert framer.pending == 5
    assert framer.feed(second[5:]) == [second]
