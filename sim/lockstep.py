"""Lockstep: the world's clock holds at a slot boundary until the next slot's plan arrives.

After publishing slot n (for n < N) the world calls `hold(n, now_s)`: the `SimClock` stops at
t0 + n dt until plan n+1 (or a later one) has arrived (`plan_arrived`), or `timeout_s` wall
seconds have passed (counted in the stats, logged; the world then goes on with the latest
shares). While it holds, the clock message is repeated every `HELD_CLOCK_PERIOD_S` wall seconds
(through the `republish_clock` callback), so that a ground loop or bridges (re)started meanwhile
learn the time and the mission start (a restarted `serve --resume` plans its next slot from
them). The timers run on the asyncio loop of the caller.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from sim.clock import SimClock
from sim.world_options import WorldStats

log = logging.getLogger(__name__)

HELD_CLOCK_PERIOD_S = 0.5
"""Wall seconds between repeats of the clock message while the world holds in lockstep."""


class Lockstep:
    """The hold of one world's clock at a slot boundary, with its wall-time timeout and the
    held-clock repeat. `republish_clock()` publishes the clock again and returns False when it
    cannot (no bus): the repeat then stops."""

    def __init__(
        self,
        clock: SimClock,
        timeout_s: float,
        stats: WorldStats,
        republish_clock: Callable[[], bool],
    ) -> None:
        self._clock = clock
        self._timeout_s = timeout_s
        self._stats = stats
        self._republish_clock = republish_clock
        self.held_slot: int | None = None
        self._hold_timer: asyncio.TimerHandle | None = None
        self._held_clock_timer: asyncio.TimerHandle | None = None

    @property
    def holding(self) -> bool:
        """True while the clock is held at a slot boundary."""
        return self.held_slot is not None

    def hold(self, n: int, now_s: float) -> None:
        """Hold the clock at `now_s` (the end of slot n) until plan n+1 arrives or time runs out."""
        self.held_slot = n
        self._stats.lockstep_holds += 1
        self._clock.hold_at(now_s)
        loop = asyncio.get_running_loop()
        self._hold_timer = loop.call_later(self._timeout_s, self._hold_timeout, n)
        self._held_clock_timer = loop.call_later(HELD_CLOCK_PERIOD_S, self._repeat_held_clock, n)

    def plan_arrived(self, latest_plan_slot: int) -> None:
        """A plan arrived: release the hold if the latest plan is for the next slot or later."""
        if self.held_slot is not None and latest_plan_slot >= self.held_slot + 1:
            self._release()

    def cancel_timers(self) -> None:
        """Cancel the timeout and the held-clock repeat (the hold itself stays)."""
        if self._hold_timer is not None:
            self._hold_timer.cancel()
            self._hold_timer = None
        if self._held_clock_timer is not None:
            self._held_clock_timer.cancel()
            self._held_clock_timer = None

    def _repeat_held_clock(self, n: int) -> None:
        """Publish the held clock again (and again) while slot n holds."""
        self._held_clock_timer = None
        if self.held_slot != n or not self._republish_clock():
            return
        loop = asyncio.get_running_loop()
        self._held_clock_timer = loop.call_later(HELD_CLOCK_PERIOD_S, self._repeat_held_clock, n)

    def _release(self) -> None:
        self.cancel_timers()
        self.held_slot = None
        self._clock.release(self._clock.now_s)

    def _hold_timeout(self, n: int) -> None:
        self._hold_timer = None
        if self.held_slot != n:
            return
        self._stats.lockstep_timeouts += 1
        self._stats.last_error = f"lockstep: no plan for slot {n + 1} within {self._timeout_s} s"
        log.warning("%s; going on with the latest shares", self._stats.last_error)
        self._release()
