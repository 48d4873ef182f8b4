"""sim/world.py on a real Zenoh session: clock, truth and detections reach an observer; lockstep."""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import socket
from collections.abc import AsyncIterator
from dataclasses import dataclass

import numpy as np
import pytest

from isac_mission.bus import BusSettings, Subscription, ZenohBus, tcp_loopback
from isac_mission.config import Scenario, parse_scenario
from isac_mission.types import SlotPlan, SolveReport
from isac_mission.wire import (
    AnyMsg,
    ClockMsg,
    DetectionMsg,
    Keys,
    PlanMsg,
    TruthMsg,
    decode_any,
    encode,
)
from sim.world import World
from sim.world_options import WorldOptions
from tests.support.ports import free_tcp_port, udp_sinks

TIMEOUT_S = 30.0
SPEED = 20.0


def scenario(m: int) -> Scenario:
    starts = [[1500.0, 2300.0], [807.0, 1100.0], [2193.0, 1100.0]][:m]
    return parse_scenario({"mission_id": "worldtest", "uavs": {"start_xy_m": starts}})


@dataclass
class Rig:
    world: World
    observer: ZenohBus
    sub: Subscription
    keys: Keys
    stop: asyncio.Event
    task: asyncio.Task[None]

    async def next_msg(self) -> AnyMsg:
        """The next message from the world (the observer's own plans are skipped)."""
        while True:
            key, data = await self.sub.get(TIMEOUT_S)
            if key != self.keys.plan:
                return decode_any(data)

    async def until(self, kind: type, slot: int) -> AnyMsg:
        """Messages until one of `kind` for `slot` (or later); returns it."""
        while True:
            msg = await self.next_msg()
            if isinstance(msg, kind) and msg.slot >= slot:
                return msg


@contextlib.asynccontextmanager
async def running_world(s: Scenario, **opts: object) -> AsyncIterator[Rig]:
    endpoint = tcp_loopback(free_tcp_port())
    keys = Keys(s.mission_id)
    with udp_sinks(s.M) as mav_base, udp_sinks(1) as gcs_base:
        observer = await ZenohBus.open_async(BusSettings.hub(endpoint))
        try:
            sub = observer.subscribe(keys.everything)
            options = WorldOptions(
                speed=SPEED,
                tick_hz=20.0,
                bus=BusSettings(connect=(endpoint,)),
                mavlink_base_port=mav_base,
                mavlink_local_base_port=0,
                gcs_port=gcs_base,
                gcs_local_base_port=0,
                **opts,  # type: ignore[arg-type]
            )
            world = World(s, options)
            stop = asyncio.Event()

            async def go() -> None:
                try:
                    await world.open()
                    await world.run(stop)
                finally:
                    await world.close()

            task = asyncio.create_task(go())
            rig = Rig(world, observer, sub, keys, stop, task)
            try:
                yield rig
            finally:
                stop.set()
                await asyncio.wait_for(task, TIMEOUT_S)
        finally:
            observer.close()
    assert world.bus is not None and world.bus.closed


async def test_world_publishes_clock_truth_and_detections_from_the_vehicles_positions() -> None:
    s = scenario(3)
    # initial_error=False: the target starts exactly at x0, as the assertions below expect.
    async with running_world(s, initial_error=False) as rig:
        got: dict[type, list[AnyMsg]] = {ClockMsg: [], TruthMsg: [], DetectionMsg: []}
        while len(got[TruthMsg]) < 3 or len(got[DetectionMsg]) < 9:
            msg = await rig.next_msg()
            got[type(msg)].append(msg)
    clocks = [m for m in got[ClockMsg] if isinstance(m, ClockMsg)]
    truths = [m for m in got[TruthMsg] if isinstance(m, TruthMsg)]
    dets = [m for m in got[DetectionMsg] if isinstance(m, DetectionMsg)]
    # clock: monotone simulation time, more often than once per slot, slot consistent with t
    ts = [c.t_s for c in clocks]
    assert ts == sorted(ts)
    assert len(clocks) > len(truths)
    for c in clocks:
        assert c.slot == math.floor(c.t_s / s.dt + 1e-9) and c.mission_t0_s == 0.0
    # truth: one per slot at t = n dt, slot 0 is x0
    for t in truths:
        assert t.t_s == pytest.approx(t.slot * s.dt)
    first = min(truths, key=lambda t: t.slot)
    if first.slot == 0:
        np.testing.assert_array_equal(first.target_x, s.x0)
    # detections: every UAV, equal shares before any plan, taken where the vehicle is
    # (on the ground at its start point: nobody flies them in this test)
    for d in dets:
        assert d.bandwidth_share == pytest.approx(1 / 3)
        np.testing.assert_allclose(d.uav_xy_m, s.uav_start_xy[d.uav], atol=1e-6)
        assert d.t_s == pytest.approx(d.slot * s.dt)
        assert d.detected
    assert {d.uav for d in dets} == {0, 1, 2}
    # and the ranges are noisy measurements of the true target
    by_slot = {t.slot: t.target_x for t in truths}
    for d in dets:
        if d.slot in by_slot:
            true_range = float(np.linalg.norm(by_slot[d.slot][:2] - d.uav_xy_m))
            assert abs(d.range_m - true_range) < 200.0


def _plan(slot: int, shares: list[float], s: Scenario) -> bytes:
    m = len(shares)
    plan = SlotPlan(
        uav_xy_m=s.uav_start_xy[:m].copy(),
        bs_of_uav=np.zeros(m, dtype=np.int64),
        bandwidth_share=np.array(shares),
        pcrb_trace=1.0,
        report=SolveReport(status="ok", solve_s=0.01),
    )
    return encode(PlanMsg.from_plan(slot, float(slot - 1) * s.dt, plan))


async def test_lockstep_holds_the_clock_until_the_next_plan_arrives() -> None:
    s = scenario(2)
    async with running_world(s, lockstep=True, lockstep_timeout_s=120.0) as rig:
        truth0 = await rig.until(TruthMsg, 0)
        assert truth0.slot == 0
        # The hold is set in the same callback that published slot 0, so it is in place now.
        assert rig.world.clock.held and rig.world.stats.lockstep_holds == 1
        # While held, no later slot appears and the clock stays at t = 0 (observed for 1 s of
        # wall time: 20 slots would pass at this speed without the hold).
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(1.0):
                while True:
                    msg = await rig.next_msg()
                    assert not isinstance(msg, TruthMsg), f"slot {msg.slot} ran while held"
                    if isinstance(msg, ClockMsg):
                        assert msg.t_s == 0.0
        assert rig.world.clock.now_s == 0.0
        # A malformed plan (three shares for two UAVs) is refused and does not release it ...
        bad = json.loads(_plan(1, [0.7, 0.3], s))
        bad["bandwidth_share"] = [0.2, 0.3, 0.5]
        rig.observer.publish(rig.keys.plan, json.dumps(bad).encode())
        # ... the valid plan for slot 1 does, and slot 1 uses its shares.
        rig.observer.publish(rig.keys.plan, _plan(1, [0.7, 0.3], s))
        # A slot's truth is published before its detections.
        truth1 = await rig.until(TruthMsg, 1)
        assert truth1.slot == 1
        dets = []
        while len(dets) < 2:
            msg = await rig.until(DetectionMsg, 1)
            assert isinstance(msg, DetectionMsg)
            dets.append(msg)
        assert {d.uav: d.bandwidth_share for d in dets} == {0: 0.7, 1: 0.3}
        assert rig.world.stats.plans_rejected == 1
        assert "plan.bandwidth_share" in rig.world.emulator.last_error  # type: ignore[union-attr]
        # and the clock holds again at slot 1 until plan 2
        assert rig.world.clock.held and rig.world.clock.now_s == pytest.approx(s.dt)


async def test_lockstep_goes_on_after_its_timeout() -> None:
    s = scenario(2)
    async with running_world(s, lockstep=True, lockstep_timeout_s=0.3) as rig:
        truth = await rig.until(TruthMsg, 2)
        assert truth.slot >= 2
        assert rig.world.stats.lockstep_timeouts >= 2
        assert "no plan for slot" in rig.world.stats.last_error


class _Client:
    """A minimal offboard client: sends MAVLink 2 from one UDP socket to each vehicle."""

    def __init__(self, world: World) -> None:
        from pymavlink.dialects.v20 import common as mavlink2

        self.m2 = mavlink2
        self.mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.world = world

    def send(self, m: int, msg: object) -> None:
        data = msg.pack(self.mav)  # type: ignore[attr-defined]
        self.sock.sendto(data, self.world.vehicles[m].offboard_address)

    def command(self, m: int, command: int, *params: float) -> None:
        p = [*params, *([0.0] * (7 - len(params)))]
        self.send(m, self.m2.MAVLink_command_long_message(m + 1, 1, command, 0, *p))

    def setpoint(self, m: int, north: float, east: float, down: float) -> None:
        self.send(
            m,
            self.m2.MAVLink_set_position_target_local_ned_message(
                0,
                m + 1,
                1,
                self.m2.MAV_FRAME_LOCAL_NED,
                0x9F8,
                north,
                east,
                down,
                0,
                0,
                0,
                0,
                0,
                0,
                0,
                0,
            ),
        )


async def test_offboard_start_begins_slot_0_once_every_vehicle_is_up_in_offboard() -> None:
    s = parse_scenario(
        {
            "mission_id": "worldtest",
            "uavs": {"start_xy_m": [[1500.0, 2300.0], [807.0, 1100.0]], "altitude_m": 20.0},
        }
    )
    async with running_world(s, start="offboard") as rig:
        first = await rig.next_msg()  # the world is open once it talks
        assert isinstance(first, ClockMsg) and first.slot == -1 and first.mission_t0_s is None
        client = _Client(rig.world)
        try:
            # Stream position setpoints at altitude H above each start point on every tick
            # (simulation time), arm, and switch to OFFBOARD: the vehicles climb to H.
            streamed = asyncio.Event()
            ticks = 0

            def stream(now_s: float, dt_s: float) -> None:
                nonlocal ticks
                for m, (x, y) in enumerate(s.uav_start_xy):
                    client.setpoint(m, y, x, -s.H)
                ticks += 1
                if ticks == 5:
                    streamed.set()

            rig.world.clock.add_tick_callback(stream)
            await asyncio.wait_for(streamed.wait(), TIMEOUT_S)
            for m in range(s.M):
                client.command(m, client.m2.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
                client.command(m, client.m2.MAV_CMD_DO_SET_MODE, 129.0, 6.0, 0.0)
            det = await rig.until(DetectionMsg, 0)
            rig.world.clock.remove_tick_callback(stream)
        finally:
            client.sock.close()
        assert isinstance(det, DetectionMsg) and det.slot == 0
        t0 = rig.world.mission_t0_s
        assert t0 is not None and t0 > 0.0 and det.t_s == pytest.approx(t0)
        for v in rig.world.vehicles:
            assert abs(v.state.altitude_m - s.H) <= 2.0
        np.testing.assert_allclose(det.uav_xy_m, s.uav_start_xy[det.uav], atol=1.0)
