"""The console's web requests: each refusal names the field at fault with a 4xx status, and a
request the bus's control model would refuse is refused before anything is sent."""

from __future__ import annotations

import json

import pytest

from isac_mission.console.requests import (
    ControlRequest,
    LoginRequest,
    RequestError,
    control_payload,
    parse_body,
)
from isac_mission.console.server import parse_address
from isac_mission.errors import ConfigError
from isac_mission.wire import ControlMsg, decode


@pytest.mark.parametrize(
    ("body", "status", "text"),
    [
        (b"{not json", 400, "body: not JSON"),
        (b"[1, 2]", 422, "body: expected a JSON object"),
        (b'{"command": "fly"}', 422, "command: 'fly' is not one of set, hold"),
        (b'{"command": 3}', 422, "command: 3 is not one of"),
        (b"{}", 422, "command: missing"),
        (b'{"command": "hold", "uav": "1"}', 422, "uav: "),
        (b'{"command": "hold", "uav": -1}', 422, "uav: "),
        (b'{"command": "hold", "uav": 1.0}', 422, "uav: "),
        (b'{"command": "set", "params": {"rate_min_mbps": "20"}}', 422, "params.rate_min_mbps: "),
        (b'{"command": "set", "paramz": {}}', 422, "paramz: unknown field"),
        (b'{"command": "set", "params": {"rate_min_mbps": 1e999}}', 422, "params.rate_min_mbps"),
        (b"x" * 5000, 413, "body: 5000 bytes"),
    ],
)
def test_a_bad_control_request_is_refused_naming_the_field(
    body: bytes, status: int, text: str
) -> None:
    with pytest.raises(RequestError) as info:
        parse_body(ControlRequest, body)
    assert info.value.status == status
    assert info.value.text.startswith(text), info.value.text
    assert info.value.field == text.partition(":")[0]


def test_a_request_the_bus_would_refuse_is_refused_with_the_bus_text() -> None:
    req = parse_body(ControlRequest, b'{"command": "set", "params": {"rate_min_mbps": -3}}')
    with pytest.raises(RequestError) as info:
        control_payload(req, slot=4, t_s=4.0, n_uavs=3)
    assert info.value.status == 422
    assert info.value.text.startswith("control.params.rate_min_mbps: ")
    req = parse_body(ControlRequest, b'{"command": "set", "params": {"speed": 3}}')
    with pytest.raises(RequestError, match=r"^control\.params\.speed: unknown parameter"):
        control_payload(req, slot=4, t_s=4.0, n_uavs=3)


def test_a_good_set_request_becomes_a_control_message_the_ground_loop_accepts() -> None:
    req = parse_body(ControlRequest, b'{"command": "set", "params": {"rate_min_mbps": 20}}')
    rid, payload = control_payload(req, slot=7, t_s=7.5, n_uavs=3, request_id="abc")
    assert rid == "abc"
    obj = json.loads(payload)
    assert obj["id"] == "abc" and obj["command"] == "set" and obj["slot"] == 7
    assert decode(ControlMsg, payload).params == {"rate_min_mbps": 20.0}


def test_login_needs_a_password() -> None:
    with pytest.raises(RequestError, match=r"^password: "):
        parse_body(LoginRequest, b'{"password": ""}')
    assert parse_body(LoginRequest, b'{"password": "x"}').password == "x"


def test_console_addresses_are_loopback_unless_opted_in() -> None:
    assert parse_address("127.0.0.1:8080").url == "http://127.0.0.1:8080/"
    assert parse_address("localhost:9000").port == 9000
    for bad, text in (
        ("8080", "expected HOST:PORT"),
        ("127.0.0.1:99999", "outside 0 to 65535"),
        ("example.org:80", "not an IP address"),
        ("0.0.0.0:8080", "not a loopback address"),
    ):
        with pytest.raises(ConfigError, match=text):
            parse_address(bad)
    assert parse_address("0.0.0.0:8080", allow_non_loopback=True).host == "0.0.0.0"
