"""Paced loops on simulation time: a change of speed while a loop waits takes effect at once."""

from __future__ import annotations

import asyncio

from isac_mission.service.bridge.pacing import run_paced


class _Speed:
    """A time source whose speed the test sets (now_s is not used by the loop)."""

    def __init__(self) -> None:
        self.speed = 1.0

    def now_s(self) -> float:
        return 0.0


async def test_a_speed_change_shortens_the_wait_for_the_next_tick() -> None:
    # 0.1 Hz at speed 1 is a 10 s wall wait; at speed 1000 the next tick is 10 ms away.
    time, ticks = _Speed(), asyncio.Queue[float]()
    loop = asyncio.get_running_loop()
    errors: list[Exception] = []
    task = asyncio.create_task(
        run_paced(0.1, lambda: ticks.put_nowait(loop.time()), time, errors.append)
    )
    try:
        first = await asyncio.wait_for(ticks.get(), timeout=5.0)
        time.speed = 1000.0
        second = await asyncio.wait_for(ticks.get(), timeout=5.0)  # half the old wait
        assert second - first < 5.0
        assert errors == []
    finally:
        task.cancel()


async def test_a_tick_that_raises_is_reported_and_the_loop_goes_on() -> None:
    time, calls = _Speed(), asyncio.Queue[int]()
    time.speed = 1000.0
    errors: list[Exception] = []
    n = 0

    def tick() -> None:
        nonlocal n
        n += 1
        calls.put_nowait(n)
        if n == 1:
            raise RuntimeError("first tick fails")

    task = asyncio.create_task(run_paced(10.0, tick, time, errors.append))
    try:
        assert await asyncio.wait_for(calls.get(), timeout=5.0) == 1
        assert await asyncio.wait_for(calls.get(), timeout=5.0) == 2
        assert [str(e) for e in errors] == ["first tick fails"]
    finally:
        task.cancel()
