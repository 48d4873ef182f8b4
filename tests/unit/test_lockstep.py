"""sim/lockstep.py: the hold at a slot boundary, its release by the next slot's plan, the wall
timeout and the held-clock repeat (on a SimClock without a bus)."""

from __future__ import annotations

import asyncio

from sim.clock import SimClock
from sim.lockstep import Lockstep
from sim.world_options import WorldStats

WAIT_S = 30.0  # generous bound for the timer callbacks on a loaded machine


async def test_a_hold_is_released_by_the_next_slots_plan_only() -> None:
    clock = SimClock(tick_hz=50.0, speed=1.0)
    stats = WorldStats()
    lockstep = Lockstep(clock, timeout_s=60.0, stats=stats, republish_clock=lambda: True)
    lockstep.hold(3, clock.now_s)
    try:
        assert lockstep.holding and lockstep.held_slot == 3
        assert clock.held and stats.lockstep_holds == 1
        lockstep.plan_arrived(3)  # a late plan for the held slot itself
        assert lockstep.holding and clock.held
        lockstep.plan_arrived(4)
        assert not lockstep.holding and not clock.held
        assert stats.lockstep_timeouts == 0 and stats.last_error == ""
    finally:
        lockstep.cancel_timers()


async def test_the_held_clock_repeats_until_the_timeout_releases_the_hold() -> None:
    clock = SimClock(tick_hz=50.0, speed=1.0)
    stats = WorldStats()
    repeated = asyncio.Event()

    def republish() -> bool:
        repeated.set()
        return True

    lockstep = Lockstep(clock, timeout_s=1.0, stats=stats, republish_clock=republish)
    timed_out = asyncio.get_running_loop().create_future()
    original = lockstep._hold_timeout

    def hold_timeout(n: int) -> None:
        original(n)
        timed_out.set_result(n)

    lockstep._hold_timeout = hold_timeout  # type: ignore[method-assign]
    lockstep.hold(0, clock.now_s)
    try:
        await asyncio.wait_for(repeated.wait(), WAIT_S)  # after HELD_CLOCK_PERIOD_S = 0.5 s
        assert lockstep.holding
        assert await asyncio.wait_for(timed_out, WAIT_S) == 0
        assert not lockstep.holding and not clock.held
        assert stats.lockstep_timeouts == 1
        assert stats.last_error == "lockstep: no plan for slot 1 within 1.0 s"
    finally:
        lockstep.cancel_timers()
