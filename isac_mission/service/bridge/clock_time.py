"""The Zenoh-fed simulation time of `serve`'s bridges: the world's `clock` messages, extrapolated.

This is the I/O side of the time base (`isac_mission.timebase` holds the protocol, the wall
clock and the slot timeline): it subscribes to `isac/<mission>/clock` on a `ZenohBus`. The
sessions a bridge or a fleet opens for itself start and stop it with `open_bus_and_clock` and
`close_bus_and_clock` (docs/frames-and-clocks.md).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable

from isac_mission.bus import BusSettings, Subscription, ZenohBus
from isac_mission.errors import IsacError, MessageError
from isac_mission.timebase import SimTime, SlotTimeline
from isac_mission.wire import ClockMsg, Keys, decode

log = logging.getLogger(__name__)


class ClockSimTime(SimTime):
    """Simulation time from the world's `clock` messages, extrapolated in between: the
    `SimTime` that follows the world's slot clock (`follows_slot_clock`).

    now_s() = t of the last clock message + (wall time since it arrived) x its speed, at most
    `max_extrapolation_s` beyond it (so time stops with the world's clock, e.g. while the world
    holds a slot boundary in lockstep), and never decreasing. A clock more than
    `restart_jump_s` behind is taken as a restarted world and followed.
    Before the first message now_s() is 0 and speed 1; `wait_ready()` waits for it.

    Feed it with `update(msg)`, or `start(bus, keys)` (`start_clock`, the port's name) to
    subscribe to `isac/<mission>/clock` (invalid payloads are counted in `invalid`, logged and
    dropped).
    """

    def __init__(
        self,
        max_extrapolation_s: float = 0.2,
        restart_jump_s: float = 5.0,
        wall: Callable[[], float] = time.monotonic,
    ) -> None:
        if not max_extrapolation_s >= 0:
            raise ValueError(f"max_extrapolation_s must be >= 0, got {max_extrapolation_s}")
        self.max_extrapolation_s = float(max_extrapolation_s)
        self.restart_jump_s = float(restart_jump_s)
        self._wall = wall
        self._msg: ClockMsg | None = None
        self._msg_wall_s = 0.0
        self._last_now_s = 0.0
        self._ready = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._sub: Subscription | None = None
        self.received = 0
        self.invalid = 0

    def update(self, msg: ClockMsg, wall_s: float | None = None) -> None:
        """Take a clock message received at wall time `wall_s` (default: now)."""
        if self._msg is not None and msg.t_s < self._last_now_s - self.restart_jump_s:
            log.warning(
                "clock went back from %.2f s to %.2f s: world restarted", self._last_now_s, msg.t_s
            )
            self._last_now_s = msg.t_s
        self._msg = msg
        self._msg_wall_s = self._wall() if wall_s is None else wall_s
        self.received += 1
        self._ready.set()

    @property
    def ready(self) -> bool:
        """True once a clock message has arrived."""
        return self._msg is not None

    def now_s(self) -> float:
        """Current simulation time, s (see the class docstring)."""
        msg = self._msg
        if msg is None:
            return self._last_now_s
        ahead = min((self._wall() - self._msg_wall_s) * msg.speed, self.max_extrapolation_s)
        now = max(self._last_now_s, msg.t_s + max(ahead, 0.0))
        self._last_now_s = now
        return now

    @property
    def speed(self) -> float:
        """The world's speed (1 before the first message)."""
        return 1.0 if self._msg is None else self._msg.speed

    @property
    def follows_slot_clock(self) -> bool:
        """True: this time follows the world's slot clock."""
        return True

    @property
    def slot_s(self) -> float | None:
        """Slot length, s (None before the first message)."""
        return None if self._msg is None else self._msg.slot_s

    @property
    def mission_t0_s(self) -> float | None:
        """Simulation time of slot 0 (None until the mission has started)."""
        return None if self._msg is None else self._msg.mission_t0_s

    def current_slot(self) -> int:
        """The slot n with t0 + n dt <= now (-1 before the mission; never None: this time
        follows the world's slot clock)."""
        msg = self._msg
        if msg is None or msg.mission_t0_s is None:
            return -1
        n = SlotTimeline(msg.mission_t0_s, msg.slot_s).slot_of(self.now_s())
        return max(-1, n, msg.slot)

    def slot_end_s(self, slot: int) -> float | None:
        """t0 + slot * dt: when the vehicles must be at plan `slot`'s waypoints (None before
        the mission has started)."""
        msg = self._msg
        if msg is None or msg.mission_t0_s is None:
            return None
        return SlotTimeline(msg.mission_t0_s, msg.slot_s).slot_end_s(slot)

    async def wait_ready(self, timeout_s: float) -> None:
        """Wait for the first clock message, `timeout_s` wall seconds; IsacError after."""
        try:
            async with asyncio.timeout(timeout_s):
                await self._ready.wait()
        except TimeoutError:
            raise IsacError(f"no clock message within {timeout_s:g} s") from None

    @property
    def running(self) -> bool:
        """True while subscribed (after start, before stop)."""
        return self._task is not None

    def start_clock(self, bus: ZenohBus, keys: Keys) -> bool:
        """`start(bus, keys)` unless `running`; True if this call started the subscription
        (then `stop_clock()` is the caller's)."""
        if self.running:
            return False
        self.start(bus, keys)
        return True

    async def stop_clock(self) -> None:
        """`stop()`: undeclare the subscription (idempotent)."""
        await self.stop()

    def start(self, bus: ZenohBus, keys: Keys) -> None:
        """Subscribe to `keys.clock` on `bus` (call on the event loop)."""
        if self._task is not None:
            return
        self._sub = bus.subscribe(keys.clock, maxsize=64)
        self._task = asyncio.create_task(self._consume(self._sub), name="clock-sim-time")

    async def stop(self) -> None:
        """Undeclare the subscription (idempotent)."""
        if self._sub is not None:
            self._sub.close()
            self._sub = None
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def _consume(self, sub: Subscription) -> None:
        async for _key, payload in sub:
            try:
                msg = decode(ClockMsg, payload)
            except MessageError as err:
                self.invalid += 1
                if self.invalid <= 5 or self.invalid % 100 == 0:
                    log.warning("clock: invalid message #%d dropped: %s", self.invalid, err)
                continue
            self.update(msg)


async def open_bus_and_clock(
    bus: ZenohBus | None, bus_settings: BusSettings | None, time: SimTime, keys: Keys
) -> tuple[ZenohBus, bool]:
    """The given bus, or a new one; starts the subscription of a time that follows the world's
    clock messages if it is not running (`SimTime.start_clock`). Returns (bus, whether this call
    started the clock)."""
    if bus is None:
        bus = await ZenohBus.open_async(bus_settings)
    return bus, time.start_clock(bus, keys)


async def close_bus_and_clock(own_bus: ZenohBus | None, started_clock: SimTime | None) -> None:
    """Undo `open_bus_and_clock`: stop the clock it started (`started_clock`: the time whose
    `start_clock` returned True, else None), close the bus it opened."""
    if started_clock is not None:
        await started_clock.stop_clock()
    if own_bus is not None:
        own_bus.close()
