"""Periodic loops on simulation time: tick every 1 / rate simulation seconds, paced on the wall.

A loop sleeps 1 / rate / speed wall seconds (at least `MIN_WALL_PERIOD_S`), paced against
deadlines so that sleep overshoot does not lower the rate; one that falls behind by more than a
period re-anchors instead of bursting. A tick that raises is reported and the loop goes on.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Final, Protocol

MIN_WALL_PERIOD_S: Final = 0.001
"""Shortest wall sleep of a periodic loop (a very fast or unpaced simulation)."""

SPEED_CHECK_WALL_S: Final = 0.05
"""How often a waiting loop looks at the time source's speed again, wall s."""

MIN_SPEED: Final = 1e-9
"""Floor of the time source's speed in wall-time divisions (a stopped clock)."""


class PaceSource(Protocol):
    """What a paced loop reads of its time source (any `SimTime`): its speed only."""

    @property
    def speed(self) -> float:
        """Simulation seconds per wall second."""
        ...


async def run_paced(
    rate_hz: float,
    tick: Callable[[], None],
    time: PaceSource,
    on_error: Callable[[Exception], None],
) -> None:
    """Call `tick()` every 1 / rate_hz simulation seconds of `time` until cancelled;
    `on_error(err)` (called inside the `except`) for a tick that raised."""
    loop = asyncio.get_running_loop()
    due = loop.time()
    while True:
        try:
            tick()
        except Exception as err:  # keep the loop alive; the caller counts and reports
            on_error(err)
        ticked, speed = loop.time(), time.speed
        period = _wall_period_s(rate_hz, speed)
        due += period
        if due < ticked - period:  # fell behind: re-anchor instead of bursting
            due = ticked
        # Sleep toward the deadline in slices: a change of speed (a ClockSimTime reads 1 until
        # the world's first clock message) shortens the wait at once instead of after it.
        while (now := loop.time()) < due:
            await asyncio.sleep(min(due - now, SPEED_CHECK_WALL_S))
            if time.speed != speed:
                speed = time.speed
                due = min(due, ticked + _wall_period_s(rate_hz, speed))


def _wall_period_s(rate_hz: float, speed: float) -> float:
    """Wall seconds between ticks at `rate_hz` simulation Hz and `speed`."""
    return max(1.0 / rate_hz / max(speed, MIN_SPEED), MIN_WALL_PERIOD_S)
