"""sim/clock.py: ticks in order at speed x real time, and the lockstep gate holds and releases.

Pacing is checked against an injected fake wall clock (its sleep advances fake time), so the
speed assertions are exact and independent of the machine's load.
"""

from __future__ import annotations

import asyncio
import itertools
import math

import pytest

from isac_mission.errors import IsacError
from isac_mission.timebase import EPS_S, UNPACED_SPEED, SlotTimeline
from sim.clock import SimClock

pytestmark = pytest.mark.timeout(20)


class FakeWall:
    """A wall clock that only moves when the clock under test sleeps (or a test says so)."""

    def __init__(self) -> None:
        self.t = 0.0

    def time(self) -> float:
        return self.t

    async def sleep(self, seconds: float) -> None:
        self.t += seconds
        await asyncio.sleep(0)


async def run_until(clock: SimClock, t_s: float) -> None:
    """Run `clock` until simulation time `t_s`, then stop it."""
    stop = asyncio.Event()
    task = asyncio.create_task(clock.run(stop))
    await asyncio.wait_for(clock.wait_until(t_s), 10.0)
    stop.set()
    await asyncio.wait_for(task, 10.0)


async def spin(n: int = 200) -> None:
    """Let the event loop run `n` times (the clock's run loop gets its turns)."""
    for _ in range(n):
        await asyncio.sleep(0)


async def test_ticks_run_callbacks_in_order_at_exact_multiples_of_dt() -> None:
    clock = SimClock(tick_hz=50.0, speed=math.inf, start_s=10.0)
    calls: list[tuple[str, float, float]] = []
    clock.add_tick_callback(lambda now, dt: calls.append(("a", now, dt)))
    clock.add_tick_callback(lambda now, dt: calls.append(("b", now, dt)))
    await run_until(clock, 11.0)
    assert len(calls) >= 2 * 50  # at full speed a few more ticks may run before stop is seen
    for k in range(50):
        a, b = calls[2 * k], calls[2 * k + 1]
        assert a[0] == "a" and b[0] == "b"
        assert a[1] == b[1] == 10.0 + (k + 1) * 0.02  # computed, not summed: exact
        assert a[2] == b[2] == 0.02


@pytest.mark.parametrize("speed", [0.5, 4.0, 25.0])
async def test_simulation_time_runs_at_speed_times_wall_time(speed: float) -> None:
    wall = FakeWall()
    clock = SimClock(tick_hz=50.0, speed=speed, wall_time=wall.time, sleep=wall.sleep)
    await run_until(clock, 2.0)
    # Within one tick of wall time of the ideal 2 s / speed.
    assert wall.t == pytest.approx(2.0 / speed, abs=0.02 / speed + 1e-9)


async def test_a_stall_re_anchors_pacing_instead_of_bursting() -> None:
    wall = FakeWall()
    clock = SimClock(tick_hz=50.0, speed=1.0, max_lag_s=0.25, wall_time=wall.time, sleep=wall.sleep)
    stamps: list[float] = []

    def on_tick(now: float, dt: float) -> None:
        stamps.append(wall.t)
        if len(stamps) == 10:
            wall.t += 2.0  # a 2 s hiccup (GC pause, loaded machine)

    clock.add_tick_callback(on_tick)
    await run_until(clock, 1.0)
    gaps = [b - a for a, b in itertools.pairwise(stamps[10:])]
    # After the stall every tick is one period apart again: no catch-up burst.
    assert min(gaps) == pytest.approx(0.02, abs=1e-9)


async def test_hold_stops_the_clock_at_the_hold_time_until_released() -> None:
    clock = SimClock(tick_hz=50.0, speed=math.inf)
    clock.hold_at(0.5)
    stop = asyncio.Event()
    task = asyncio.create_task(clock.run(stop))
    await asyncio.wait_for(clock.wait_until(0.5), 10.0)
    await spin()
    assert clock.now_s == pytest.approx(0.5) and clock.held
    assert not clock.tick(), "a manual tick is gated too"
    clock.release(0.5)
    await asyncio.wait_for(clock.wait_until(1.0), 10.0)
    assert not clock.held
    stop.set()
    await asyncio.wait_for(task, 10.0)


async def test_hold_between_ticks_stops_at_the_last_tick_before_it() -> None:
    clock = SimClock(tick_hz=50.0, speed=math.inf)
    clock.hold_at(0.51)
    stop = asyncio.Event()
    task = asyncio.create_task(clock.run(stop))
    await asyncio.wait_for(clock.wait_until(0.5), 10.0)
    await spin()
    assert clock.now_s == pytest.approx(0.5)
    stop.set()  # stop also ends a held clock
    await asyncio.wait_for(task, 10.0)


async def test_a_newer_release_releases_older_holds_and_early_releases_count() -> None:
    clock = SimClock(tick_hz=50.0, speed=math.inf)
    clock.hold_at(0.2)
    clock.hold_at(0.4)
    clock.release(0.4)  # releases both
    clock.release(0.8)
    clock.hold_at(0.6)  # already released: no-op (the plan arrived before the gate was set)
    clock.hold_at(1.0)
    stop = asyncio.Event()
    task = asyncio.create_task(clock.run(stop))
    await asyncio.wait_for(clock.wait_until(1.0), 10.0)
    await spin()
    assert clock.now_s == pytest.approx(1.0) and clock.held
    stop.set()
    await asyncio.wait_for(task, 10.0)


async def test_wait_until_resolves_at_the_requested_time() -> None:
    clock = SimClock(tick_hz=50.0, speed=math.inf)
    seen: list[float] = []

    async def waiter(t: float) -> None:
        await clock.wait_until(t)
        seen.append(clock.now_s)

    stop = asyncio.Event()
    waiters = [asyncio.create_task(waiter(t)) for t in (0.3, 0.1, 0.2)]
    task = asyncio.create_task(clock.run(stop))
    await asyncio.wait_for(asyncio.gather(*waiters), 10.0)
    stop.set()
    await asyncio.wait_for(task, 10.0)
    assert seen == pytest.approx([0.1, 0.2, 0.3])


def test_invalid_arguments_are_refused() -> None:
    with pytest.raises(IsacError, match="tick_hz"):
        SimClock(tick_hz=0.0)
    with pytest.raises(IsacError, match="speed"):
        SimClock(speed=-1.0)
    clock = SimClock()
    with pytest.raises(IsacError, match="speed"):
        clock.speed = math.nan
    with pytest.raises(IsacError, match="not registered"):
        clock.remove_tick_callback(lambda now, dt: None)
    with pytest.raises(IsacError, match="finite"):
        clock.hold_at(math.inf)


def test_manual_ticks_advance_and_callbacks_can_be_removed() -> None:
    clock = SimClock(tick_hz=10.0)
    calls: list[float] = []

    def cb(now: float, dt: float) -> None:
        calls.append(now)

    clock.add_tick_callback(cb)
    assert clock.tick() and clock.tick()
    clock.remove_tick_callback(cb)
    clock.tick()
    assert calls == pytest.approx([0.1, 0.2]) and clock.ticks == 3


def test_a_slot_boundary_that_rounds_past_a_tick_is_reached_at_that_tick() -> None:
    # Slot 3 of 0.1 s slots ends at 3 x 0.1 = 0.30000000000000004 s; tick 15 of a 50 Hz clock
    # is 15 x 0.02 = 0.3 s, a hair before it. With the time base's one epsilon the clock
    # counts that tick as the boundary: a wait for it resolves there, and a hold there stops
    # the clock at tick 15 (not one tick later, not one earlier).
    boundary = SlotTimeline(0.0, 0.1).slot_end_s(3)
    clock = SimClock(tick_hz=50.0)
    assert boundary > 15 * clock.dt_s
    clock.hold_at(boundary)
    while clock.tick():
        pass
    assert clock.ticks == 15
    assert clock.now_s + EPS_S >= boundary


def test_sim_time_adapts_the_clock_to_the_services_time_source() -> None:
    clock = SimClock(tick_hz=10.0, speed=math.inf)
    t = clock.sim_time()
    clock.tick()
    assert t.now_s() == clock.now_s
    assert t.speed == UNPACED_SPEED  # inf: as fast as possible
    clock.speed = 4.0
    assert t.speed == 4.0
