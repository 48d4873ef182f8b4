"""What the simulated world (`sim.world.World`) publishes over its slots, with no network.

`record_world(name, seed, slots)` builds the world of scenario `name` for noise seed `seed`,
gives it a bus that only records, no vehicles to open (their actual positions come from
`positions_at`, a path of its own per slot), and plans with unequal shares at
`PLANS_AT` (taken before the slot they are for), then runs slots 0..slots-1 through the world's
own slot boundary (`_run_due_slots`). It returns every (key, payload) the world published, in
order: truth, reports and clock of each slot.

The recording reads only the world's construction, its `open`, its emulator's plan intake and
its slot boundary, so that the same function records a tree before and after a change to the
world's insides: `python -m tests.support.world_messages OUT.json` writes `recordings()`, as
tests/unit/data/world_slots.json was written (tests/unit/test_world_slots.py compares).
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import sys
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

import sim.world
from isac_mission.config import Scenario, load_scenario
from isac_mission.types import FloatArray, SlotPlan, SolveReport
from isac_mission.wire import PlanMsg, encode
from sim.world import World
from sim.world_options import WorldOptions

PLANS_AT = {2: (0.5, 0.3, 0.2), 5: (0.2, 0.2, 0.6), 7: (0.1, 0.6, 0.3), 30: (0.4, 0.4, 0.2)}
"""Slot -> the shares of UAVs 0..2 of the plan for it (the others share what is left)."""


@dataclass
class RecordingBus:
    """The world's bus: records every publication, subscribes to nothing."""

    sent: list[tuple[str, bytes]] = field(default_factory=list)
    closed: bool = False

    def publish(self, key: str, payload: bytes) -> None:
        self.sent.append((key, bytes(payload)))

    def close(self) -> None:
        self.closed = True


def shares(s: Scenario, first: tuple[float, ...]) -> FloatArray:
    """[M] the plan's shares: `first` for UAVs 0..2 scaled to 0.7, the rest 0.3 equally (M > 3)."""
    if s.M <= len(first):
        return np.array(first[: s.M]) / sum(first[: s.M])
    head = 0.7 * np.array(first) / sum(first)
    return np.concatenate([head, np.full(s.M - len(first), 0.3 / (s.M - len(first)))])


def positions_at(s: Scenario, n: int) -> FloatArray:
    """[M, 2] the vehicles' actual positions at slot n (m): each leaves its start on a line."""
    m = np.arange(s.M, dtype=float)[:, None]
    step = np.concatenate([7.0 + m, -3.0 + 2.0 * m], axis=1)
    return np.asarray(s.uav_start_xy + n * step, dtype=float)


def plan_payload(s: Scenario, slot: int, eta: FloatArray) -> bytes:
    plan = SlotPlan(
        uav_xy_m=positions_at(s, slot),
        bs_of_uav=np.zeros(s.M, dtype=np.int64),
        bandwidth_share=eta,
        pcrb_trace=1.0,
        report=SolveReport(status="ok"),
    )
    return encode(PlanMsg.from_plan(slot, 0.0, plan))


def record_world(
    name: str, seed: int, slots: int, monkeypatch: pytest.MonkeyPatch
) -> list[tuple[str, bytes]]:
    """Every (key, payload) the world of scenario `name`, seed `seed`, publishes at slots
    0..slots-1 (its clock at each slot boundary included)."""
    s = load_scenario(name)
    bus = RecordingBus()

    class Bus:
        @staticmethod
        async def open_async(settings: Any) -> RecordingBus:
            return bus

    current = [0]
    monkeypatch.setattr(sim.world, "ZenohBus", Bus)
    monkeypatch.setattr(sim.world, "positions_xy_m", lambda vehicles: positions_at(s, current[0]))
    world = World(s, WorldOptions(seed=seed))
    world.vehicles = []  # no sockets: the positions come from positions_at

    async def go() -> None:
        await world.open()
        emulator = world.emulator
        assert emulator is not None
        for n in range(slots):
            if n in PLANS_AT:
                emulator.on_plan_payload(plan_payload(s, n, shares(s, PLANS_AT[n])))
            current[0] = n
            world._run_due_slots(world._slot_time(n))
        await world.close()

    asyncio.run(go())
    assert world.stats.slots == slots
    return bus.sent


def digest(sent: list[tuple[str, bytes]]) -> str:
    """sha256 over every key and payload, in order."""
    h = hashlib.sha256()
    for key, payload in sent:
        h.update(key.encode() + b"\0" + payload + b"\0")
    return h.hexdigest()


SCENARIOS = ("paper", "multi-target")
SEED = 7
SLOTS = 64
"""Slots recorded: 0..63, past the shipped scenarios' last slot N = 60."""
SHOWN_SLOTS = 6
"""Slots kept message by message (the rest by their digest)."""


def recordings(monkeypatch: pytest.MonkeyPatch) -> dict[str, dict[str, Any]]:
    """Per scenario: the number of messages and their digest over `SLOTS` slots, and the
    messages of the first `SHOWN_SLOTS` slots as (key, payload text)."""
    out: dict[str, dict[str, Any]] = {}
    for name in SCENARIOS:
        sent = record_world(name, SEED, SLOTS, monkeypatch)
        with monkeypatch.context() as mp:
            shown = record_world(name, SEED, SHOWN_SLOTS, mp)
        assert shown == sent[: len(shown)]
        out[name] = {
            "seed": SEED,
            "slots": SLOTS,
            "messages": len(sent),
            "sha256": digest(sent),
            "first_slots": SHOWN_SLOTS,
            "first": [[key, payload.decode()] for key, payload in shown],
        }
    return out


if __name__ == "__main__":
    with pytest.MonkeyPatch.context() as mp:
        data = recordings(mp)
    with open(sys.argv[1], "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1)
