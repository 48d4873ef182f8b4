"""The operator's messages: control requests (each command's fields), replies, fleet commands."""

from __future__ import annotations

import json

import pytest

from isac_mission import wire
from isac_mission.errors import MessageError

BASE = {"schema": "isac/1", "type": "control", "slot": 3, "t": 30.0}


def _payload(**fields: object) -> bytes:
    return json.dumps({**BASE, **fields}).encode()


@pytest.mark.parametrize(
    "msg",
    [
        wire.ControlMsg.set_params(3, 30.0, "r1", rate_min_mbps=20.0),
        wire.ControlMsg(3, 30.0, "r2", "hold"),
        wire.ControlMsg(3, 30.0, "r3", "hold", 1),
        wire.ControlMsg(3, 30.0, "r4", "resume"),
        wire.ControlMsg(3, 30.0, "r5", "land", 2),
        wire.ControlMsg(-1, 0.0, "r6", "release", 0),
    ],
)
def test_every_command_round_trips(msg: wire.ControlMsg) -> None:
    data = wire.encode(msg)
    assert wire.decode(wire.ControlMsg, data, n_uavs=3) == msg
    assert wire.decode_any(data) == msg
    read = wire.read_request(data, n_uavs=3)
    assert read.msg == msg and read.error is None and read.request_id == msg.request_id


@pytest.mark.parametrize(
    ("fields", "text"),
    [
        ({"id": "a", "command": "fly"}, "control.command: 'fly' is not a command"),
        ({"id": "a", "command": "release"}, "control.uav: missing (command 'release'"),
        ({"id": "a", "command": "hold", "uav": 3}, "control.uav: 3 is outside [0, 2]"),
        ({"id": "a", "command": "hold", "uav": True}, "control.uav: expected an integer"),
        (
            {"id": "a", "command": "land", "params": {"rate_min_mbps": 3}},
            "control.params: not allowed with command 'land'",
        ),
        ({"id": "a", "command": "set"}, "control.params: missing"),
        (
            {"id": "a", "command": "set", "uav": 1, "params": {"rate_min_mbps": 3}},
            "control.uav: not allowed with command 'set'",
        ),
        (
            {"id": "a", "command": "set", "params": {"rate_min_mbps": 0}},
            "control.params.rate_min_mbps: 0 is below 0.001",
        ),
        ({"id": "", "command": "hold"}, "control.id: empty"),
        ({"id": "x" * 65, "command": "hold"}, "control.id: 65 characters, limit 64"),
        ({"command": "hold"}, "control.id: missing"),
    ],
)
def test_a_malformed_request_names_the_field(fields: dict[str, object], text: str) -> None:
    with pytest.raises(MessageError) as err:
        wire.decode(wire.ControlMsg, _payload(**fields), n_uavs=3)
    assert str(err.value).startswith(text)
    read = wire.read_request(_payload(**fields), n_uavs=3)
    assert read.msg is None and read.error is not None
    assert str(read.error).startswith(text)
    readable = fields.get("id")
    expect = readable if isinstance(readable, str) and 1 <= len(readable) <= 64 else None
    assert read.request_id == expect


def test_an_unreadable_request_has_no_id() -> None:
    for payload in (b"not json", b"[1]", _payload(id=7, command="hold")):
        read = wire.read_request(payload)
        assert read.msg is None and read.request_id is None and read.error is not None


def test_reply_and_fleet_round_trip_and_are_checked() -> None:
    reply = wire.ControlReplyMsg(3, 30.0, "r1", "hold", True, "ok", "held", (1,))
    assert wire.decode(wire.ControlReplyMsg, wire.encode(reply)) == reply
    refused = wire.ControlReplyMsg(3, 30.0, None, None, False, "payload: not JSON", "nothing")
    assert wire.decode_any(wire.encode(refused)) == refused
    fleet = wire.FleetMsg(3, 30.0, "r1", "land", (0, 2))
    assert wire.decode(wire.FleetMsg, wire.encode(fleet), n_uavs=3) == fleet
    with pytest.raises(MessageError, match=r"fleet\.uavs\[1\]: 5 is outside \[0, 2\]"):
        wire.decode(
            wire.FleetMsg, wire.encode(wire.FleetMsg(3, 30.0, "r", "hold", (0, 5))), n_uavs=3
        )
    with pytest.raises(MessageError, match=r"fleet\.uavs"):
        wire.encode(wire.FleetMsg(3, 30.0, "r", "hold", ()))


def test_telemetry_carries_the_override() -> None:
    import numpy as np

    tel = wire.TelemetryMsg(
        4,
        4.0,
        1,
        np.zeros(2),
        20.0,
        np.zeros(2),
        "hold",
        True,
        False,
        "ok",
        override="operator: HOLD",
    )
    assert wire.decode(wire.TelemetryMsg, wire.encode(tel)).override == "operator: HOLD"
    obj = json.loads(wire.encode(tel))
    del obj["override"]  # optional: an older sender's telemetry
    assert wire.decode(wire.TelemetryMsg, json.dumps(obj).encode()).override == ""
