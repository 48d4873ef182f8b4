"""The ground loop's answers to operator requests (service/ground/control.py), without a network:
what is accepted or refused, what is sent to the bridges, and what is planned around."""

from __future__ import annotations

from typing import Any

import numpy as np

from isac_mission.config import Scenario
from isac_mission.service.ground.control import ControlDesk
from isac_mission.service.ground.exclusion import VehicleWatch
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.wire import (
    ControlMsg,
    ControlReplyMsg,
    FleetMsg,
    Keys,
    TelemetryMsg,
    decode,
    encode,
)

KEYS = Keys("paper")


class Bus:
    """Records what the desk publishes (the desk only calls publish)."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, bytes]] = []

    def publish(self, key: str, payload: bytes) -> None:
        self.sent.append((key, payload))


class State:
    """The two things the desk reads of the mission state: slot and scenario."""

    def __init__(self, s: Scenario) -> None:
        self.slot = 4
        self.scenario = s

    def set_scenario(self, s: Scenario) -> None:
        self.scenario = s


def tel(m: int, override: str = "", mode: str = "offboard", landed: bool = False) -> TelemetryMsg:
    return TelemetryMsg(
        4,
        40.0,
        m,
        np.zeros(2),
        100.0,
        np.zeros(2),
        mode,
        not landed,
        landed,
        "ok",
        override=override,
    )


def desk(paper: Scenario) -> tuple[ControlDesk, Bus, VehicleWatch, State]:
    report = GroundReport()
    watch = VehicleWatch(3, GroundSettings(plan_rate_factor=1.05), report)
    for m in range(3):
        watch.on_telemetry(tel(m))
    bus, state = Bus(), State(paper)
    d = ControlDesk(KEYS, bus, watch, report, lambda: state, lambda: 40.0)  # type: ignore[arg-type]
    return d, bus, watch, state


def ask(d: ControlDesk, bus: Bus, rid: str, command: str, uav: int | None = None) -> Any:
    bus.sent.clear()
    reply = d.on_request(encode(ControlMsg(4, 40.0, rid, command, uav)))
    keys = [k for k, _ in bus.sent]
    assert keys[-1] == KEYS.control_reply
    assert decode(ControlReplyMsg, bus.sent[-1][1]) == reply
    fleet = [decode(FleetMsg, p) for k, p in bus.sent if k == KEYS.fleet]
    return reply, fleet


def test_hold_resume_land_release(paper: Scenario) -> None:
    d, bus, watch, _ = desk(paper)
    reply, fleet = ask(d, bus, "h1", "hold", 1)
    assert reply.accepted and reply.vehicles == (1,)
    assert [(f.command, f.uavs, f.request_id) for f in fleet] == [("hold", (1,), "h1")]
    assert watch.held == {1: "control: hold"}
    watch.update(40.0)
    assert watch.excluded == {1: "control: hold"}
    reply, fleet = ask(d, bus, "h2", "hold", 1)
    assert not reply.accepted and reply.reason == "vehicle 1 is held already" and fleet == []
    reply, fleet = ask(d, bus, "h3", "hold")  # all: the ones not held yet
    assert reply.accepted and reply.vehicles == (0, 2)
    reply, fleet = ask(d, bus, "r1", "resume")
    assert reply.accepted and reply.vehicles == (0, 1, 2) and fleet[0].command == "resume"
    assert watch.held == {}
    reply, fleet = ask(d, bus, "r2", "resume")
    assert not reply.accepted and reply.reason == "no vehicle is held by a control 'hold'"
    reply, fleet = ask(d, bus, "l1", "land", 2)
    assert reply.accepted and fleet[0].uavs == (2,) and "out of the mission" in reply.effect
    for command in ("resume", "release", "hold", "land"):
        reply, fleet = ask(d, bus, f"x-{command}", command, 2)
        assert not reply.accepted and "out of the mission" in reply.reason, (command, reply)
        assert fleet == []
    counters = d.report.counters
    assert counters["operator commands"] == 4 and counters["operator commands refused"] == 6


def test_an_overridden_vehicle_is_released_not_held_or_resumed(paper: Scenario) -> None:
    d, bus, watch, _ = desk(paper)
    reply, _ = ask(d, bus, "rel0", "release", 0)
    assert not reply.accepted and "flown by the service" in reply.reason
    watch.on_telemetry(tel(0, "operator: HOLD", "hold"))
    for command in ("hold", "land"):
        reply, fleet = ask(d, bus, command, command, 0)
        assert not reply.accepted and "not the service's (operator: HOLD)" in reply.reason
        assert fleet == []
    reply, _ = ask(d, bus, "res0", "resume", 0)
    assert not reply.accepted and "release it" in reply.reason
    reply, fleet = ask(d, bus, "rel1", "release", 0)
    assert reply.accepted and [f.command for f in fleet] == ["release"]
    assert "was: operator: HOLD" in reply.effect
    # Landed by its own RTL: out of the mission, no release.
    watch.on_telemetry(tel(1, "landed", "rtl", landed=True))
    watch.update(40.0)
    reply, _ = ask(d, bus, "rel2", "release", 1)
    assert not reply.accepted and "on the ground" in reply.reason


def test_set_and_malformed_requests(paper: Scenario) -> None:
    d, bus, watch, state = desk(paper)
    reply = d.on_request(encode(ControlMsg.set_params(4, 40.0, "s1", rate_min_mbps=8.0)))
    assert reply.accepted and reply.effect == "R_th = 8 Mbit/s from slot 6 on"
    assert state.scenario.r_th == 8e6 * 1.05
    bus.sent.clear()
    reply = d.on_request(b'{"schema": "isac/1", "type": "control", "slot": 0, "t": 0}')
    assert (reply.request_id, reply.accepted) == (None, False)
    assert reply.reason == "control.id: missing" and reply.effect == "nothing was executed"
    assert [k for k, _ in bus.sent] == [KEYS.control_reply]  # nothing sent to the bridges
    assert d.report.counters["rejected control.id"] == 1
    assert watch.held == {} and state.scenario.r_th == 8e6 * 1.05
