"""Harness for the simulated-vehicle integration tests: autopilots on a fast SimClock.

The simulation (a `SimClock` ticking every `Autopilot`) runs in its own thread with its own
event loop, so a test can use blocking clients (pymavlink) or its own asyncio loop (MAVSDK)
without stalling the vehicles. Tests observe `Autopilot.state` (an immutable snapshot replaced
each step) and wait with `wait_until`, which polls a condition until it holds or a deadline
passes.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Callable
from typing import TypeVar

from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from sim.clock import SimClock
from tests.support.loop_calls import call_on_loop

T = TypeVar("T")

SIM_SPEED = 4.0
"""Simulation seconds per wall second in these tests."""
SIM_TICK_HZ = 50.0
"""The vehicles' simulation tick rate (Hz of simulation time)."""


def wait_until(condition: Callable[[], T], timeout_s: float, what: str, poll_s: float = 0.01) -> T:
    """Poll `condition` until it returns a truthy value (returned) or `timeout_s` wall s pass."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        time.sleep(poll_s)


async def async_wait_until(
    condition: Callable[[], T], timeout_s: float, what: str, poll_s: float = 0.02
) -> T:
    """`wait_until` for coroutines: polls without blocking the caller's event loop."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = condition()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")
        await asyncio.sleep(poll_s)


class SimRunner:
    """Autopilots stepped by a SimClock in a background thread with its own event loop."""

    def __init__(self, settings: list[AutopilotSettings], speed: float = SIM_SPEED) -> None:
        self.autopilots = [Autopilot(s) for s in settings]
        self.clock = SimClock(tick_hz=SIM_TICK_HZ, speed=speed)
        for ap in self.autopilots:
            self.clock.add_tick_callback(ap.step)
        self._loop = asyncio.new_event_loop()
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="sim", daemon=True)

    def _main(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._run())
        except BaseException as exc:  # surfaced by start()/stop()
            self._error = exc
            self._ready.set()
        finally:
            self._loop.close()

    async def _run(self) -> None:
        self._stop = asyncio.Event()
        for ap in self.autopilots:
            await ap.open()
        self._ready.set()
        try:
            await self.clock.run(self._stop)
        finally:
            for ap in self.autopilots:
                await ap.close()

    def start(self) -> SimRunner:
        self._thread.start()
        if not self._ready.wait(10.0) or self._error is not None:
            raise RuntimeError(f"simulation did not start: {self._error!r}")
        return self

    def call(self, fn: Callable[[], T]) -> T:
        """Run `fn()` on the simulation's loop thread and return its result."""
        return call_on_loop(self._loop, fn, 10.0)

    def stop(self) -> None:
        if self._thread.is_alive() and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(timeout=10.0)
        if self._error is not None:
            raise self._error
