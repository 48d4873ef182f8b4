"""An operator's track priority (docs/bus.md, `control`, `priority`), without a network: the
request model (which fields the command takes, the weight's range, refusals naming the field),
the ground loop's desk (set_priority called with the request's values, a ValueError refused
with its text), the `priority` of `track` and `track_set` (optional, 1 when absent, written only
when it is not 1), the console's request path and view, and the replay's read-only priority."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from isac_mission import wire
from isac_mission.config import Scenario, load_scenario
from isac_mission.console.replay import _priorities
from isac_mission.console.requests import (
    ControlRequest,
    RequestError,
    control_payload,
    parse_body,
)
from isac_mission.console.state import MissionView
from isac_mission.errors import MessageError
from isac_mission.service.ground.control import ControlDesk
from isac_mission.service.ground.exclusion import VehicleWatch
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.wire.schema import message_schemas

BASE = {"schema": "isac/1", "type": "control", "slot": 3, "t": 30.0}
KEYS = wire.Keys("paper")
P = np.diag([4.0, 9.0, 1.0, 1.0])


def _payload(**fields: object) -> bytes:
    return json.dumps({**BASE, **fields}).encode()


# ---------------------------------------------------------------- the request model


def test_a_priority_request_round_trips() -> None:
    msg = wire.ControlMsg.priority(3, 30.0, "p1", track=2, weight=5.0)
    data = wire.encode(msg)
    assert json.loads(data) == {
        **BASE,
        "id": "p1",
        "command": "priority",
        "params": {"weight": 5.0},
        "track": 2,
    }
    assert wire.decode(wire.ControlMsg, data, n_uavs=3) == msg
    assert wire.decode_any(data) == msg
    read = wire.read_request(data, n_uavs=3)
    assert read.msg == msg and read.command == "priority"
    assert (read.msg.track, read.msg.params) == (2, {"weight": 5.0})
    # The bounds are in: 0 (not planned for) and 10.
    for weight in (0, 10, 2.5):
        ok = wire.read_request(
            _payload(id="a", command="priority", track=1, params={"weight": weight})
        )
        assert ok.msg is not None and ok.msg.params == {"weight": float(weight)}


@pytest.mark.parametrize(
    ("fields", "text"),
    [
        (
            {"command": "priority", "track": 2, "params": {"weight": 12}},
            "control.params.weight: 12 is above 10",
        ),
        (
            {"command": "priority", "track": 2, "params": {"weight": -0.5}},
            "control.params.weight: -0.5 is below 0",
        ),
        (
            {"command": "priority", "track": 2, "params": {"weight": "5"}},
            "control.params.weight: expected a number, got str",
        ),
        (
            {"command": "priority", "track": 2, "params": {"weight": True}},
            "control.params.weight: expected a number, got bool",
        ),
        (
            {"command": "priority", "params": {"weight": 5}},
            "control.track: missing (command 'priority' names one track)",
        ),
        (
            {"command": "priority", "track": 0, "params": {"weight": 5}},
            "control.track: 0 is outside [1, 1000000000]",
        ),
        (
            {"command": "priority", "track": 2.0, "params": {"weight": 5}},
            "control.track: expected an integer",
        ),
        (
            {"command": "priority", "track": 2},
            "control.params: missing (command 'priority' needs a weight)",
        ),
        (
            {"command": "priority", "track": 2, "params": {"rate_min_mbps": 5}},
            "control.params.rate_min_mbps: unknown parameter (known: weight)",
        ),
        (
            {"command": "priority", "track": 2, "uav": 1, "params": {"weight": 5}},
            "control.uav: not allowed with command 'priority'",
        ),
        # A weight for a command that takes none, or takes other parameters.
        (
            {"command": "hold", "params": {"weight": 5}},
            "control.params: not allowed with command 'hold'",
        ),
        (
            {"command": "set", "params": {"weight": 5}},
            "control.params.weight: unknown parameter (known: rate_min_mbps)",
        ),
        ({"command": "land", "track": 2}, "control.track: not allowed with command 'land'"),
        (
            {"command": "set", "track": 2, "params": {"rate_min_mbps": 5}},
            "control.track: not allowed with command 'set'",
        ),
    ],
)
def test_a_malformed_priority_request_names_the_field(fields: dict[str, Any], text: str) -> None:
    payload = _payload(id="p", **fields)
    with pytest.raises(MessageError) as err:
        wire.decode(wire.ControlMsg, payload, n_uavs=3)
    assert str(err.value).startswith(text), str(err.value)
    read = wire.read_request(payload, n_uavs=3)
    assert read.msg is None and read.request_id == "p"
    assert str(read.error).startswith(text)


def test_the_schema_has_the_command_its_track_and_the_tracks_priority() -> None:
    schemas = message_schemas()
    control = schemas["control"]["properties"]
    assert "priority" in control["command"]["enum"]
    track = next(s for s in control["track"]["anyOf"] if s.get("type") == "integer")
    assert (track["minimum"], track["maximum"]) == (1, wire.MAX_SLOT)
    assert "track" not in schemas["control"]["required"]
    priority = schemas["track"]["properties"]["priority"]
    assert (priority["minimum"], priority["maximum"], priority["default"]) == (0.0, 10.0, 1.0)
    assert "priority" not in schemas["track"]["required"]
    entry = next(iter(schemas["track_set"]["$defs"].values()))
    assert entry["properties"]["priority"]["maximum"] == wire.MAX_PRIORITY
    assert "priority" not in entry["required"]


# ---------------------------------------------------------------- the tracks carry it


def _track(priority: float | None = None) -> wire.TrackMsg:
    extra = {} if priority is None else {"priority": priority}
    return wire.TrackMsg(7, 7.0, np.zeros(4), P, np.linalg.inv(P), 13.0, **extra)


def _entry(track_id: int, priority: float | None = None) -> wire.TrackEntry:
    extra = {} if priority is None else {"priority": priority}
    return wire.TrackEntry(track_id, True, np.arange(4.0), P, 13.0, **extra)


def test_a_track_carries_its_priority_and_an_old_one_reads_as_priority_one() -> None:
    old = wire.encode(_track())
    assert b"priority" not in old  # the bytes of a mission whose operator sets none
    assert wire.encode(_track(1.0)) == old  # 1 is not written
    assert wire.decode(wire.TrackMsg, old).priority == wire.DEFAULT_PRIORITY == 1.0
    data = wire.encode(_track(4.5))
    assert json.loads(data)["priority"] == 4.5
    assert wire.decode(wire.TrackMsg, data).priority == 4.5
    assert wire.decode(wire.TrackMsg, wire.encode(_track(0.0))).priority == 0.0
    msg = wire.TrackSetMsg(7, 7.0, (_entry(1), _entry(2, 0.0), _entry(5, 10.0)))
    data = wire.encode(msg)
    written = json.loads(data)["tracks"]
    assert ["priority" in e for e in written] == [False, True, True]
    got = wire.decode(wire.TrackSetMsg, data)
    assert [e.priority for e in got.tracks] == [1.0, 0.0, 10.0]
    assert wire.encode(wire.decode_any(data)) == data


@pytest.mark.parametrize(
    ("kind", "priority", "text"),
    [
        ("track", 12, "track.priority: 12 is above 10"),
        ("track", -1, "track.priority: -1 is below 0"),
        ("track", None, "track.priority: expected a number, got NoneType"),
        ("track_set", 10.5, "track_set.tracks[1].priority: 10.5 is above 10"),
        ("track_set", "high", "track_set.tracks[1].priority: expected a number, got str"),
    ],
)
def test_a_priority_out_of_range_is_refused_naming_the_track(
    kind: str, priority: object, text: str
) -> None:
    if kind == "track":
        obj = json.loads(wire.encode(_track()))
        obj["priority"] = priority
    else:
        obj = json.loads(wire.encode(wire.TrackSetMsg(7, 7.0, (_entry(1), _entry(2)))))
        obj["tracks"][1]["priority"] = priority
    with pytest.raises(MessageError) as err:
        wire.decode(kind, json.dumps(obj).encode())
    assert str(err.value).startswith(text), str(err.value)


# ---------------------------------------------------------------- the ground loop's desk


class Bus:
    def __init__(self) -> None:
        self.sent: list[tuple[str, bytes]] = []

    def publish(self, key: str, payload: bytes) -> None:
        self.sent.append((key, payload))


class Mission:
    """A stand-in for MissionState's part the desk uses: slot, scenario, set_priority (as the
    real one: ValueError naming what is wrong)."""

    def __init__(self, s: Scenario, tracks: tuple[int, ...]) -> None:
        self.slot = 12
        self.next_planned_slot = 14  # slot 13's job already made
        self.scenario = s
        self.tracks = tracks
        self.calls: list[tuple[int, float]] = []

    def set_scenario(self, s: Scenario) -> None:
        self.scenario = s

    def set_priority(self, track_id: int, weight: float) -> None:
        if track_id not in self.tracks:
            raise ValueError(f"no track {track_id}")
        self.calls.append((track_id, weight))


def _desk(paper: Scenario) -> tuple[ControlDesk, Bus, Mission]:
    report = GroundReport()
    watch = VehicleWatch(3, GroundSettings(), report)
    bus, mission = Bus(), Mission(paper, (1, 2))
    desk = ControlDesk(KEYS, bus, watch, report, lambda: mission, lambda: 120.0)  # type: ignore[arg-type]
    return desk, bus, mission


def test_the_desk_sets_the_priority_and_says_from_which_slot(paper: Scenario) -> None:
    desk, bus, mission = _desk(paper)
    reply = desk.on_request(wire.encode(wire.ControlMsg.priority(12, 120.0, "p1", 2, 5.0)))
    assert mission.calls == [(2, 5.0)]
    assert reply.accepted and reply.request_id == "p1" and reply.command == "priority"
    assert reply.reason == "priority accepted"
    assert reply.effect == "track 2: priority 5 from slot 14 on"
    assert reply.vehicles == () and reply.slot == 12
    assert [k for k, _ in bus.sent] == [KEYS.control_reply]  # nothing for the bridges
    assert wire.decode(wire.ControlReplyMsg, bus.sent[-1][1]) == reply
    zero = desk.on_request(wire.encode(wire.ControlMsg.priority(12, 120.0, "p2", 1, 0.0)))
    assert zero.accepted and zero.effect.startswith("track 1: priority 0 from slot 14 on")
    assert "not planned for, still kept clear of" in zero.effect
    assert mission.calls == [(2, 5.0), (1, 0.0)]
    assert desk.report.counters["operator commands"] == 2


def test_the_desk_refuses_with_the_mission_states_reason_and_sets_nothing(
    paper: Scenario,
) -> None:
    desk, bus, mission = _desk(paper)
    reply = desk.on_request(wire.encode(wire.ControlMsg.priority(12, 120.0, "p7", 7, 2.0)))
    assert not reply.accepted and reply.request_id == "p7"
    assert reply.reason == "no track 7" and reply.effect == "nothing was executed"
    assert mission.calls == []
    # A weight out of range never reaches the mission state: the model refuses it.
    bus.sent.clear()
    bad = _payload(id="p8", command="priority", track=2, params={"weight": 12})
    reply = desk.on_request(bad)
    assert not reply.accepted and reply.request_id == "p8" and reply.command == "priority"
    assert reply.reason == "control.params.weight: 12 is above 10"
    assert [k for k, _ in bus.sent] == [KEYS.control_reply] and mission.calls == []
    counters = desk.report.counters
    assert counters["operator commands refused"] == 2 and counters["operator commands"] == 0
    assert counters["rejected control.params.weight"] == 1


# ---------------------------------------------------------------- the console


def test_the_console_sends_a_priority_the_ground_loop_reads() -> None:
    body = b'{"command": "priority", "track": 3, "params": {"weight": 2.5}}'
    req = parse_body(ControlRequest, body)
    rid, payload = control_payload(req, slot=5, t_s=5.0, n_uavs=3, request_id="c1")
    read = wire.read_request(payload, n_uavs=3)
    assert rid == "c1" and read.msg is not None
    assert (read.msg.command, read.msg.track, read.msg.params) == ("priority", 3, {"weight": 2.5})
    for bad, text in (
        (b'{"command": "priority", "track": 3, "params": {"weight": 11}}', "control.params.weight"),
        (b'{"command": "priority", "params": {"weight": 1}}', "control.track"),
        (b'{"command": "hold", "track": 3}', "control.track"),
    ):
        with pytest.raises(RequestError) as err:
            control_payload(parse_body(ControlRequest, bad), slot=5, t_s=5.0, n_uavs=3)
        assert err.value.status == 422 and err.value.field == text, err.value.text
    with pytest.raises(RequestError) as err:
        parse_body(ControlRequest, b'{"command": "priority", "track": 0, "params": {"weight": 1}}')
    assert err.value.field == "track"


def test_the_console_view_gives_every_track_its_priority() -> None:
    view = MissionView(load_scenario("paper").trace_config(), clock=lambda: 1.0)
    view.ingest(KEYS.track, wire.encode(_track()))
    assert [t["priority"] for t in view.latest["tracks"]["tracks"]] == [1.0]
    assert view.latest["track"]["priority"] == 1.0
    view.ingest(KEYS.track, wire.encode(_track(3.0)))
    assert [t["priority"] for t in view.latest["tracks"]["tracks"]] == [3.0]
    tracks = wire.TrackSetMsg(8, 8.0, (_entry(4), _entry(9, 0.0)))
    view.ingest(KEYS.track, wire.encode(tracks))
    got = {t["id"]: t["priority"] for t in view.latest["tracks"]["tracks"]}
    assert got == {4: 1.0, 9: 0.0}


def test_a_replay_reads_the_priority_its_trace_records() -> None:
    raw = {
        "tracks": [
            {"id": 1, "priority": 4},
            {"id": 2},
            {"id": 3, "priority": True},
            {"id": 5, "priority": 0.0},
            "junk",
        ]
    }
    assert _priorities(raw) == {1: 4.0, 5: 0.0}
    assert _priorities({}) == {}
