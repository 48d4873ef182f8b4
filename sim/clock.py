"""Simulation clock: fixed ticks of simulation time, paced against the wall clock (pure asyncio).

`SimClock` advances simulation time in ticks of `1 / tick_hz` seconds and calls every registered
tick callback with `(now_s, dt_s)` after each advance, in registration order; `now_s` is
`start_s + k * dt_s` after the k-th tick (computed, not summed, so it does not drift): the ticks
are the slots of an `isac_mission.timebase.SlotTimeline(start_s, dt_s)`, and every comparison of
simulation times uses the time base's one epsilon (`timebase.reached`).

Pacing: with `speed` = s, tick k is due at wall time `anchor + (k - k_anchor) * dt_s / s`. When
the loop falls behind by more than `max_lag_s` of wall time the pace is re-anchored instead of
bursting to catch up (simulation time then runs slower than asked; it never jumps).
`speed=math.inf` runs ticks back to back, yielding to the event loop after each one so sockets
are still served.

Lockstep gate: `hold_at(t_s)` stops the clock from advancing past `t_s` (it reaches the last
tick at or before `t_s` and waits) until `release(t)` is called with any `t >= t_s`. A release
that comes before its hold (the plan arrived early) makes that hold a no-op. The world uses this
to wait at a slot boundary until that slot's plan has arrived.

No sockets, no threads: `run(stop)` is a coroutine for the caller's event loop. The wall clock
and the sleep are injectable so tests can drive pacing deterministically.
"""

from __future__ import annotations

import asyncio
import bisect
import heapq
import itertools
import math
from collections.abc import Awaitable, Callable

from isac_mission.errors import IsacError
from isac_mission.timebase import FuncTime, SlotTimeline, reached

TickCallback = Callable[[float, float], None]
"""Called as `callback(now_s, dt_s)` after each tick: advance your state from now_s - dt_s."""


class SimClock:
    """Simulation time in fixed ticks, at `speed` x real time, with a lockstep gate.

    Args:
        tick_hz: Ticks per second of simulation time (physics rate), Hz.
        speed: Simulation seconds per wall second; `math.inf` = as fast as possible.
        start_s: Simulation time before the first tick, s.
        max_lag_s: Wall-time lag, s, beyond which pacing re-anchors instead of catching up.
        wall_time: Monotonic wall clock, s (default: the running loop's `time()`).
        sleep: Coroutine function sleeping a wall duration, s (default `asyncio.sleep`).
    """

    def __init__(
        self,
        tick_hz: float = 50.0,
        speed: float = 1.0,
        start_s: float = 0.0,
        max_lag_s: float = 0.25,
        wall_time: Callable[[], float] | None = None,
        sleep: Callable[[float], Awaitable[None]] | None = None,
    ) -> None:
        if not (math.isfinite(tick_hz) and tick_hz > 0.0):
            raise IsacError(f"SimClock: tick_hz must be finite and > 0 (got {tick_hz})")
        self._check_speed(speed)
        self._ticks_grid = SlotTimeline(float(start_s), 1.0 / tick_hz)
        """Tick k ends at simulation time start_s + k dt_s: the ticks are slots of the grid."""
        self._ticks = 0
        self._speed = float(speed)
        self._max_lag_s = float(max_lag_s)
        self._wall_time = wall_time
        self._sleep: Callable[[float], Awaitable[None]] = sleep or asyncio.sleep
        self._callbacks: list[TickCallback] = []
        self._holds: list[float] = []  # sorted hold times, s
        self._released_s = -math.inf
        self._waiters: list[tuple[float, int, asyncio.Future[None]]] = []
        self._waiter_ids = itertools.count()
        self._wake: asyncio.Event | None = None
        self._anchor: tuple[float, int] | None = None  # (wall s, tick index)

    # -- properties --------------------------------------------------------------------------

    @property
    def now_s(self) -> float:
        """Current simulation time, s."""
        return self._ticks_grid.slot_end_s(self._ticks)

    @property
    def dt_s(self) -> float:
        """Tick length, s of simulation time."""
        return self._ticks_grid.dt_s

    @property
    def ticks(self) -> int:
        """Number of ticks run so far."""
        return self._ticks

    @property
    def speed(self) -> float:
        """Simulation seconds per wall second (`math.inf`: as fast as possible)."""
        return self._speed

    @speed.setter
    def speed(self, value: float) -> None:
        self._check_speed(value)
        self._speed = float(value)
        self._anchor = None
        self._poke()

    def sim_time(self) -> FuncTime:
        """This clock as a `SimTime` source (its now_s and speed), for the service's bridges."""
        return FuncTime(lambda: self.now_s, lambda: self.speed)

    @property
    def held(self) -> bool:
        """True when the gate stops the next tick."""
        return self._blocking_hold() is not None

    # -- callbacks ---------------------------------------------------------------------------

    def add_tick_callback(self, callback: TickCallback) -> None:
        """Call `callback(now_s, dt_s)` after every tick, after those registered before it."""
        self._callbacks.append(callback)

    def remove_tick_callback(self, callback: TickCallback) -> None:
        """Stop calling `callback`; raises IsacError if it was not registered."""
        try:
            self._callbacks.remove(callback)
        except ValueError:
            raise IsacError(f"SimClock: callback {callback!r} is not registered") from None

    # -- lockstep gate -----------------------------------------------------------------------

    def hold_at(self, t_s: float) -> None:
        """Do not advance past simulation time `t_s` until `release(t)` with `t >= t_s`."""
        if not math.isfinite(t_s):
            raise IsacError(f"SimClock.hold_at: t_s must be finite (got {t_s})")
        if t_s <= self._released_s:
            return
        bisect.insort(self._holds, float(t_s))

    def release(self, t_s: float) -> None:
        """Release every hold at or before simulation time `t_s` (and future holds up to it)."""
        self._released_s = max(self._released_s, float(t_s))
        cut = bisect.bisect_right(self._holds, self._released_s)
        del self._holds[:cut]
        self._poke()

    # -- advancing ---------------------------------------------------------------------------

    def tick(self) -> bool:
        """Advance one tick now (ignoring pace) unless the gate holds; True if it advanced."""
        if self._blocking_hold() is not None:
            return False
        self._ticks += 1
        now = self.now_s
        dt_s = self._ticks_grid.dt_s
        for callback in list(self._callbacks):
            callback(now, dt_s)
        while self._waiters and reached(now, self._waiters[0][0]):
            _, _, fut = heapq.heappop(self._waiters)
            if not fut.done():
                fut.set_result(None)
        return True

    async def wait_until(self, t_s: float) -> None:
        """Return once simulation time has reached `t_s` (at once if it has)."""
        if reached(self.now_s, t_s):
            return
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        heapq.heappush(self._waiters, (float(t_s), next(self._waiter_ids), fut))
        await fut

    async def run(self, stop: asyncio.Event) -> None:
        """Tick at the configured pace until `stop` is set."""
        loop = asyncio.get_running_loop()
        wall = self._wall_time or loop.time
        self._wake = asyncio.Event()
        self._anchor = None
        try:
            while not stop.is_set():
                if self._blocking_hold() is not None:
                    self._anchor = None
                    await self._wait_wake_or_stop(stop)
                    continue
                if math.isinf(self._speed):
                    self.tick()
                    await self._sleep(0)
                    continue
                now_wall = wall()
                if self._anchor is None:
                    self._anchor = (now_wall, self._ticks)
                wall0, tick0 = self._anchor
                due = wall0 + (self._ticks + 1 - tick0) * self._ticks_grid.dt_s / self._speed
                delay = due - now_wall
                if delay > 0.0:
                    # Sleep in short pieces so stop, release and speed changes are seen soon.
                    await self._sleep(min(delay, 0.05))
                    continue
                if -delay > self._max_lag_s:
                    self._anchor = (now_wall, self._ticks)
                self.tick()
                await self._sleep(0)
        finally:
            self._wake = None

    # -- internals ---------------------------------------------------------------------------

    @staticmethod
    def _check_speed(speed: float) -> None:
        if math.isnan(speed) or speed <= 0.0:
            raise IsacError(f"SimClock: speed must be > 0 or inf (got {speed})")

    def _blocking_hold(self) -> float | None:
        """The earliest hold that the next tick would pass, if any."""
        if not self._holds:
            return None
        nxt = self._ticks_grid.slot_end_s(self._ticks + 1)
        first = self._holds[0]
        return None if reached(first, nxt) else first

    def _poke(self) -> None:
        if self._wake is not None:
            self._wake.set()

    async def _wait_wake_or_stop(self, stop: asyncio.Event) -> None:
        wake = self._wake
        if wake is None:  # pragma: no cover - run() sets it
            return
        wake.clear()
        if self._blocking_hold() is None:
            return
        waiters = [asyncio.ensure_future(stop.wait()), asyncio.ensure_future(wake.wait())]
        try:
            await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for w in waiters:
                w.cancel()
