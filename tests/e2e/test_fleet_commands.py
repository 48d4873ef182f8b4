"""Fleet commands on `control` during a live mission, each with its reply (docs/bus.md).

Real parts: the embedded world's PX4-like vehicles over loopback UDP MAVLink, the bridges and the
ground loop of `run`, a Zenoh client observer that sends the requests, and a real MAVProxy on the
ground-station port through which the vehicles' modes are watched (independently of the service).

Order: two malformed requests (unreadable, and a readable id with a bad field) are refused and
change nothing; `set` R_th; `hold` vehicle 0 (HOLD, planned around), a second `hold` of it is
refused; `resume` (all) brings it back; `hold` all, `resume` all; `land` vehicle 2 (it lands, the
mission goes on with 0 and 1); `resume` and `release` of the landed vehicle are refused.
"""

from __future__ import annotations

import asyncio
import socket
from pathlib import Path

import numpy as np

from isac_mission.bus import ZenohBus, tcp_loopback
from isac_mission.cli.embedded import run_embedded
from isac_mission.config import Scenario
from isac_mission.service.assembly import LiveOptions
from isac_mission.wire import Keys, PlanMsg
from tests.support.mavproxy import MavlinkListener, MavProxy
from tests.support.mission_watch import MissionWatch, open_client
from tests.support.ports import free_port_block, sitl_ports

WAIT_S = 240.0
"""Generous wall-clock bound of every wait (a loaded 2-core machine)."""


def _out(plan: PlanMsg, m: int) -> bool:
    return int(plan.plan.bs_of_uav[m]) == -1 and float(plan.plan.bandwidth_share[m]) == 0.0


def _in(plan: PlanMsg, m: int) -> bool:
    return int(plan.plan.bs_of_uav[m]) >= 0 and float(plan.plan.bandwidth_share[m]) > 0.0


async def test_each_fleet_command_and_a_malformed_one_get_their_replies(
    paper: Scenario, tmp_path: Path
) -> None:
    s = paper.with_changes(N=120, H=20.0)  # a low altitude: a short climb and landing
    ports = sitl_ports(s.M)
    endpoint = tcp_loopback(free_port_block(1, socket.SOCK_STREAM))
    opts = LiveOptions(
        speed=5.0,
        lockstep=True,
        seed=4,
        out_dir=tmp_path,
        zenoh_endpoint=endpoint,
        **ports.world_kwargs(),
    )
    stop = asyncio.Event()
    with MavlinkListener() as seen, MavProxy(f"udpin:127.0.0.1:{ports.gcs}", [seen.out]):
        mission = asyncio.create_task(run_embedded(s, opts, stop))
        try:
            with await open_client(endpoint, WAIT_S) as observer:
                await _operate(s, Keys(s.mission_id), seen, observer)
        finally:
            stop.set()
            result = await asyncio.wait_for(mission, timeout=WAIT_S)
    counters = result.report.counters
    assert counters["operator commands"] == 6, counters
    assert counters["operator commands refused"] == 5, counters
    assert counters["rejected payload not JSON"] == 1 and counters["rejected control.uav"] == 1


async def _operate(s: Scenario, keys: Keys, seen: MavlinkListener, bus: ZenohBus) -> None:
    async with MissionWatch(bus, keys) as w:
        await w.until(lambda: len(w.plans) >= 4, WAIT_S, "four plans")

        async def planned_again(m: int, what: str) -> None:
            n = len(w.plans)
            await w.until(lambda: any(_in(p, m) for _, p in w.plans[n:]), WAIT_S, what)

        async def left_out(m: int, what: str) -> None:
            n = len(w.plans)
            await w.until(lambda: any(_out(p, m) for _, p in w.plans[n:]), WAIT_S, what)

        # Malformed: refused with the field at fault, nothing executed.
        bad = await w.send_raw(b"{not json", None, WAIT_S)
        assert not bad.accepted and bad.command is None
        assert bad.reason.startswith("payload: not JSON") and bad.effect == "nothing was executed"
        n_before = len(w.plans)
        raw = (
            b'{"schema": "isac/1", "type": "control", "slot": 0, "t": 0, "id": "bad-1",'
            b' "command": "hold", "uav": 9}'
        )
        bad = await w.send_raw(raw, "bad-1", WAIT_S)
        assert not bad.accepted and bad.command == "hold" and bad.vehicles == ()
        assert bad.reason == "control.uav: 9 is outside [0, 2]"
        await w.until(lambda: len(w.plans) >= n_before + 3, WAIT_S, "three more plans")
        assert all(_in(p, m) for _, p in w.plans[n_before:] for m in range(s.M))
        assert {seen.mode(i) for i in (1, 2, 3)} == {"offboard"}

        # set
        reply = await w.request("set-1", "set", rate_min_mbps=8.0)
        assert reply.accepted and reply.effect.startswith("R_th = 8 Mbit/s from slot")

        # hold one, a second hold refused, resume all
        reply = await w.request("hold-0", "hold", 0)
        assert reply.accepted and reply.vehicles == (0,) and "held (PX4 HOLD)" in reply.effect
        await asyncio.to_thread(seen.wait_for_mode, 1, "hold", 60.0)
        await left_out(0, "vehicle 0 planned around")
        tel = w.last_telemetry(0)
        assert tel is not None and tel.override == "control: hold"
        again = await w.request("hold-0b", "hold", 0)
        assert not again.accepted and again.reason == "vehicle 0 is held already"
        reply = await w.request("resume-all", "resume")
        assert reply.accepted and reply.vehicles == (0,)
        await asyncio.to_thread(seen.wait_for_mode, 1, "offboard", 60.0)
        await planned_again(0, "vehicle 0 planned again after resume")

        # hold all, resume all
        reply = await w.request("hold-all", "hold")
        assert reply.accepted and reply.vehicles == (0, 1, 2)
        for sysid in (1, 2, 3):
            await asyncio.to_thread(seen.wait_for_mode, sysid, "hold", 60.0)
        n = len(w.plans)
        await w.until(
            lambda: any(p.plan.report.status == "operator hold" for _, p in w.plans[n:]),
            WAIT_S,
            "a plan with every vehicle held (status 'operator hold')",
        )
        # What the reply said: nobody served (share 0, no BS), and no error or fallback.
        held = next(p.plan for _, p in w.plans[n:] if p.plan.report.status == "operator hold")
        assert not held.report.fallback
        np.testing.assert_array_equal(held.bandwidth_share, np.zeros(s.M))
        np.testing.assert_array_equal(held.bs_of_uav, np.full(s.M, -1))
        reply = await w.request("resume-all-2", "resume")
        assert reply.accepted and reply.vehicles == (0, 1, 2)
        for sysid in (1, 2, 3):
            await asyncio.to_thread(seen.wait_for_mode, sysid, "offboard", 60.0)
        n = len(w.plans)
        await w.until(
            lambda: any(all(_in(p, m) for m in range(s.M)) for _, p in w.plans[n:]),
            WAIT_S,
            "every vehicle planned again",
        )

        # land one: it lands, the others fly on
        reply = await w.request("land-2", "land", 2)
        assert reply.accepted and reply.vehicles == (2,) and "out of the mission" in reply.effect
        await w.until(
            lambda: (t := w.last_telemetry(2)) is not None and t.landed,
            WAIT_S,
            "vehicle 2 landed",
        )
        n = len(w.plans)
        await w.until(lambda: len(w.plans) >= n + 3, WAIT_S, "three plans after the landing")
        for _, p in w.plans[n:]:
            assert _out(p, 2) and _in(p, 0) and _in(p, 1), p.slot
        refused = await w.request("resume-2", "resume", 2)
        assert not refused.accepted and "out of the mission" in refused.reason
        refused = await w.request("release-2", "release", 2)
        assert not refused.accepted and "out of the mission" in refused.reason
        assert any(h.vehicles.get(2, "").startswith("excluded: control: land") for h in w.health)
