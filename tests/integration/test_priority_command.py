"""An operator's `priority` command (docs/bus.md, `control`) on a real GroundLoop against the
simulated world over real Zenoh on loopback (as test_ground_loop.py, no MAVLink bridge), sent by a
client observer session as an operator's tool would:

- a weight out of range is refused naming the field, and a track that does not exist is refused
  with the mission state's reason; nothing changes and the loop goes on;
- a good one is accepted with what was done (`track 1: priority 4 from slot k on`), and the
  `track` messages of slot k on carry `priority` 4 (those put before the request: 1); the one
  track, planned for alone, still weighs 1 in the planner's objective;
- priority 0: the track is not planned for from the slot its reply names: those slots' plans
  hold the fleet, saying why, without asking the planner, and their tracks carry priority 0;
  priority 1 again: planned for again from the slot that reply names;
- every slot of the mission is flown, and the counters say three commands accepted, two refused.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path

from isac_mission.bus import BusSettings, ZenohBus, tcp_loopback
from isac_mission.config import Scenario
from isac_mission.errors import MessageError
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.slot import Method, SlotInput, plan_slot
from isac_mission.service.ground.loop import GroundLoop
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.types import SlotPlan
from isac_mission.wire import (
    ControlMsg,
    ControlReplyMsg,
    Keys,
    PlanMsg,
    TrackMsg,
    decode_any,
    encode,
)
from sim.world import run_world
from sim.world_options import WorldOptions
from tests.support.mission_watch import open_client
from tests.support.ports import sitl_ports

WAIT_S = 60.0
"""Generous wall-clock bound of every wait (a loaded 2-core machine)."""
SLOTS = 60
ZERO_HOLD = "every confirmed track has priority 0"
"""What the plan of a slot whose one track is at priority 0 says (planning/tracks.py)."""


class Recorder:
    """The planner the ground loop is given: plan_slot, keeping each call's target weights."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.weights: list[list[float]] = []

    def __call__(self, inp: SlotInput, kit: SolverKit, method: Method) -> SlotPlan:
        with self.lock:
            self.weights.append([float(b.weight) for b in inp.targets])
        return plan_slot(inp, kit, method)

    def calls(self) -> list[list[float]]:
        with self.lock:
            return list(self.weights)


class Seen:
    """What the operator's session received, in order: replies and tracks (one subscription on
    every key, so the ground loop's messages arrive in the order it put them)."""

    def __init__(self) -> None:
        self.events: list[ControlReplyMsg | TrackMsg | PlanMsg] = []
        self.changed = asyncio.Event()

    async def pump(self, bus: ZenohBus, keys: Keys) -> None:
        async for _key, payload in bus.messages(keys.everything):
            with contextlib.suppress(MessageError):  # the test's own malformed request
                msg = decode_any(payload)
                if isinstance(msg, ControlReplyMsg | TrackMsg | PlanMsg):
                    self.events.append(msg)
                    self.changed.set()

    def of(self, kind: type[ControlReplyMsg | TrackMsg | PlanMsg]) -> list[object]:
        return [e for e in self.events if isinstance(e, kind)]

    async def until(self, pred: Callable[[], bool], what: str) -> None:
        deadline = time.monotonic() + WAIT_S
        while not pred():
            if time.monotonic() > deadline:
                raise AssertionError(f"not within {WAIT_S} s: {what}")
            self.changed.clear()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self.changed.wait(), 1.0)

    async def ask(self, bus: ZenohBus, keys: Keys, payload: bytes, rid: str) -> ControlReplyMsg:
        bus.publish(keys.control, payload)

        def reply() -> ControlReplyMsg | None:
            return next(
                (e for e in self.events if isinstance(e, ControlReplyMsg) and e.request_id == rid),
                None,
            )

        await self.until(lambda: reply() is not None, f"the reply to {rid}")
        got = reply()
        assert got is not None
        return got


async def test_a_priority_is_planned_with_from_the_slot_its_reply_names(
    paper: Scenario, free_tcp_port: int, tmp_path: Path
) -> None:
    s = paper.with_changes(N=SLOTS)
    endpoint = tcp_loopback(free_tcp_port)
    keys = Keys(s.mission_id)
    planner = Recorder()
    seen = Seen()
    with ZenohBus.open(BusSettings.hub(endpoint)) as bus:
        settings = GroundSettings(trace_path=tmp_path / "live.jsonl", planner=planner)
        loop = GroundLoop(s, bus, settings)
        opts = WorldOptions(
            speed=10.0,
            lockstep=True,
            lockstep_timeout_s=20.0,
            bus=BusSettings(connect=(endpoint,)),
            **sitl_ports(3).world_kwargs(),
            seed=5,
        )
        stop_world, stop_ground = asyncio.Event(), asyncio.Event()
        with await open_client(endpoint, WAIT_S) as operator:
            pump = asyncio.create_task(seen.pump(operator, keys))
            world = asyncio.create_task(run_world(s, opts, stop_world))
            ground = asyncio.create_task(loop.run(stop_ground))
            try:
                await seen.until(lambda: len(seen.of(TrackMsg)) >= 3, "three tracks")
                replies = await _operate(seen, operator, keys)
                report = await asyncio.wait_for(ground, timeout=240)
            finally:
                stop_ground.set()
                stop_world.set()
                await asyncio.wait_for(world, timeout=30)
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(ground, timeout=30)
                pump.cancel()
    counters = report.counters
    assert counters["slots"] == SLOTS, counters
    assert counters["operator commands"] == 3, counters
    assert counters["operator commands refused"] == 2, counters
    assert counters["rejected control.params.weight"] == 1, counters
    assert not [k for k in counters if k.startswith("internal")], counters

    # Each request was executed when the loop had processed slot S (its reply's slot): the plans
    # and tracks from slot S + 2 on (the reply's "from slot") are made with it, and those up to
    # the next request's slot too.
    (s4, k4), (s0, k0), (s1, k1) = ((r.slot, _from_slot(r)) for r in replies)
    assert (k4, k0, k1) == (s4 + 2, s0 + 2, s1 + 2)
    assert k4 <= s0 and k0 <= s1
    tracks = {e.slot: e for e in seen.events if isinstance(e, TrackMsg)}
    plans = {e.slot: e for e in seen.events if isinstance(e, PlanMsg)}
    assert sorted(tracks) == list(range(1, SLOTS + 1)) and sorted(plans) == sorted(tracks)
    at = seen.events.index(replies[0])
    before = [e for e in seen.events[:at] if isinstance(e, TrackMsg)]
    assert before and all(t.priority == 1.0 for t in before)
    want = {n: 4.0 for n in range(k4, s0 + 1)} | {n: 0.0 for n in range(k0, s1 + 1)}
    want |= {n: 1.0 for n in range(k1, SLOTS + 1)}
    assert {n: tracks[n].priority for n in want} == want
    # Priority 0: the plans of those slots hold the fleet, and say why; the others do not.
    held = {n for n, p in plans.items() if ZERO_HOLD in p.reason}
    assert set(range(k0, s1 + 1)) <= held, sorted(held)
    assert held <= set(range(s0 + 1, s1 + 2)), sorted(held)
    # The planner was asked for every other slot, the one track weighing 1 whatever its priority
    # (a track planned for alone weighs 1: tracking/priorities.py).
    calls = planner.calls()
    assert len(calls) == SLOTS - len(held), (len(calls), sorted(held))
    assert all(w == [1.0] for w in calls), calls


def _from_slot(reply: ControlReplyMsg) -> int:
    m = re.match(r"track 1: priority [0-9.]+ from slot (\d+) on", reply.effect)
    assert m is not None, reply.effect
    return int(m.group(1))


async def _operate(seen: Seen, bus: ZenohBus, keys: Keys) -> list[ControlReplyMsg]:
    """Send the five requests (two refused); the replies of the three accepted."""
    # A weight out of range: refused by the model, naming the field; nothing executed.
    raw = {
        "schema": "isac/1",
        "type": "control",
        "slot": 0,
        "t": 0.0,
        "id": "bad-weight",
        "command": "priority",
        "track": 1,
        "params": {"weight": 12},
    }
    bad = await seen.ask(bus, keys, json.dumps(raw).encode(), "bad-weight")
    assert not bad.accepted and bad.command == "priority"
    assert bad.reason == "control.params.weight: 12 is above 10"
    assert bad.effect == "nothing was executed"

    # A track that does not exist: refused with the mission state's reason.
    n = len(seen.of(TrackMsg))
    missing = ControlMsg.priority(0, 0.0, "no-track", track=7, weight=2.0)
    bad = await seen.ask(bus, keys, encode(missing), "no-track")
    assert not bad.accepted and bad.reason.startswith("no track 7"), bad.reason
    assert bad.effect == "nothing was executed"
    await seen.until(lambda: len(seen.of(TrackMsg)) >= n + 2, "two more tracks: the loop goes on")

    replies = []
    for rid, weight in (("weight-4", 4.0), ("weight-0", 0.0), ("weight-1", 1.0)):
        msg = ControlMsg.priority(0, 0.0, rid, track=1, weight=weight)
        reply = await seen.ask(bus, keys, encode(msg), rid)
        assert reply.accepted and reply.reason == "priority accepted", reply
        assert reply.command == "priority" and reply.vehicles == ()
        k = _from_slot(reply)
        assert reply.effect.startswith(f"track 1: priority {weight:g} from slot {k} on")
        assert ("not planned for, still kept clear of" in reply.effect) == (weight == 0.0)
        replies.append(reply)
        await seen.until(
            lambda k=k: any(isinstance(e, PlanMsg) and e.slot >= k + 2 for e in seen.events),
            f"the plan of slot {k + 2}",
        )
    return replies
