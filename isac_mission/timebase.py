"""One time base: simulation-time sources and the one slot timeline (pure, no I/O).

Time sources (`SimTime`): `now_s()` in simulation seconds, non-decreasing, and `speed`
(simulation seconds per wall second, > 0); and what the bridges need to know of the world's slot
clock, so that no caller asks a time for its type: `follows_slot_clock`, `current_slot()` and
`slot_end_s(n)` (None without a slot clock), `ready` and `wait_ready(timeout_s)`, and
`start_clock(bus, keys)` / `stop_clock()` for a time fed by messages. `SimTime`'s own bodies are
those of a free-running time (no slot clock, always ready, nothing to start): a class that
subclasses `SimTime` inherits them and implements `now_s` and `speed` only. `WallTime` is the
wall clock for real vehicles, `FuncTime` adapts any clock function (e.g. an in-process
`sim.clock.SimClock`). The clock fed by the world's Zenoh `clock` messages is I/O and lives with
the bridge (`isac_mission.service.bridge.clock_time.ClockSimTime`).

Slots (`SlotTimeline(t0_s, dt_s)`): slot n covers simulation time (t0 + (n-1) dt, t0 + n dt];
its end `slot_end_s(n) = t0 + n dt` is the boundary at which its detections are taken and by
which the vehicles must be at plan n's waypoints. `slot_of(t_s)` is the latest slot whose end
has been reached at `t_s`: floor((t - t0) / dt + EPS_S), so slot 0 before the first boundary.

Every comparison of simulation times in the project uses the one tolerance `EPS_S` (1 ns), through
`reached(now_s, t_s)`: a time computed as t0 + n dt and a clock computed as start + k tick may
differ in the last bits where they mean the same instant (docs/frames-and-clocks.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final, Protocol

if TYPE_CHECKING:  # types of the clock subscription's arguments only: no I/O here
    from isac_mission.bus import ZenohBus
    from isac_mission.wire import Keys

EPS_S: Final = 1e-9
"""The one tolerance, s, of simulation-time comparisons (slot boundaries, holds, waits)."""

UNPACED_SPEED: Final = 1e6
"""`FuncTime.speed` of a clock running as fast as possible (speed inf, 0 or NaN)."""


def reached(now_s: float, t_s: float) -> bool:
    """True when simulation time `now_s` has reached `t_s` (within EPS_S), both in s."""
    return now_s + EPS_S >= t_s


class SimTime(Protocol):
    """A source of simulation time: `now_s()` (s, non-decreasing) and `speed` (simulation
    seconds per wall second, > 0), and what it knows of the world's slot clock.

    The members after `speed` have bodies: those of a free-running time, which follows no
    world's slot clock (its slots are unknown: None), is always ready and has no clock to start
    or stop. A class that subclasses `SimTime` inherits them (`WallTime`, `FuncTime`); a time fed
    by the world's clock messages overrides them (`ClockSimTime`).
    """

    def now_s(self) -> float:
        """Current simulation time, s."""
        ...

    @property
    def speed(self) -> float:
        """Simulation seconds per wall second."""
        ...

    @property
    def follows_slot_clock(self) -> bool:
        """True when this time follows a world's slot clock, which knows the mission's slots
        (False: a free-running time; `current_slot()` and `slot_end_s()` are then None)."""
        return False

    def current_slot(self) -> int | None:
        """The latest slot n whose end t0 + n dt the world's clock has reached (-1 before the
        mission starts); None when this time follows no slot clock."""
        return None

    def slot_end_s(self, slot: int) -> float | None:
        """End of slot `slot`, t0 + slot dt in simulation seconds: when the vehicles must be at
        plan `slot`'s waypoints. None when this time follows no slot clock or the mission start
        t0 is not known yet."""
        return None

    @property
    def ready(self) -> bool:
        """True when `now_s()` is the simulation time (a time fed by clock messages: once the
        first has arrived; before, it reads 0). A free-running time is always ready."""
        return True

    async def wait_ready(self, timeout_s: float) -> None:
        """Return once `ready`, waiting at most `timeout_s` wall seconds (IsacError after).
        A free-running time returns at once."""
        return None

    def start_clock(self, bus: ZenohBus, keys: Keys) -> bool:
        """Start following the world's clock messages (`keys.clock` on `bus`) if this time
        needs them and does not follow them yet; call on the event loop. True if this call
        started it (then `stop_clock()` is the caller's); False for a free-running time."""
        return False

    async def stop_clock(self) -> None:
        """Stop following the world's clock messages (idempotent); nothing for a free-running
        time."""
        return None


class WallTime(SimTime):
    """The wall clock as simulation time, for real vehicles: Unix seconds (anchored once to
    `time.time()` and advanced by the monotonic clock, so it never jumps), speed 1. Free-running:
    no slot clock, always ready (`SimTime`'s bodies).

    Args:
        epoch_s: Subtracted from the Unix time (e.g. the mission start), s.
    """

    def __init__(self, epoch_s: float = 0.0) -> None:
        self._offset_s = time.time() - time.monotonic() - epoch_s

    def now_s(self) -> float:
        """Wall time since `epoch_s`, s."""
        return time.monotonic() + self._offset_s

    @property
    def speed(self) -> float:
        """1: wall time."""
        return 1.0


class FuncTime(SimTime):
    """Simulation time from functions: `now()` in s, `speed()` (or a fixed number).
    Free-running: no slot clock, always ready (`SimTime`'s bodies).

    For an in-process clock, e.g. `FuncTime(lambda: clock.now_s, lambda: clock.speed)`.
    """

    def __init__(self, now: Callable[[], float], speed: Callable[[], float] | float = 1.0) -> None:
        self._now = now
        self._speed = speed

    def now_s(self) -> float:
        """`now()`."""
        return float(self._now())

    @property
    def speed(self) -> float:
        """`speed()` (or the fixed value); math.inf (or a value not > 0) becomes UNPACED_SPEED."""
        value = float(self._speed() if callable(self._speed) else self._speed)
        return value if math.isfinite(value) and value > 0 else UNPACED_SPEED


@dataclass(frozen=True)
class SlotTimeline:
    """Slots of `dt_s` seconds from `t0_s` (simulation time of slot 0's end, the mission start).

    Slot n covers (t0 + (n-1) dt, t0 + n dt]. A periodic grid (e.g. clock messages every
    `period` s from 0) is a timeline too: `SlotTimeline(0.0, period)`.
    """

    t0_s: float
    dt_s: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.t0_s) and math.isfinite(self.dt_s) and self.dt_s > 0.0):
            raise ValueError(
                f"SlotTimeline: t0_s must be finite and dt_s finite and > 0 "
                f"(got t0_s={self.t0_s}, dt_s={self.dt_s})"
            )

    def slot_of(self, t_s: float) -> int:
        """The latest slot n whose end t0 + n dt has been reached at `t_s` (within EPS_S);
        negative before t0."""
        return math.floor((t_s - self.t0_s) / self.dt_s + EPS_S)

    def slot_start_s(self, n: int) -> float:
        """Start of slot n (the end of slot n - 1), s."""
        return self.slot_end_s(n - 1)

    def slot_end_s(self, n: int) -> float:
        """End of slot n: t0 + n dt, s."""
        return self.t0_s + n * self.dt_s


LATE_PLAN_SLOTS = 1.0
"""A plan whose slot ended more than this many slots ago is dropped as late, not flown (the
bridges drop it; the ground loop records the slot's fallback as "late")."""


def plan_is_late(slot_end_s: float | None, now_s: float, slot_s: float) -> bool:
    """Whether a plan whose slot ends at `slot_end_s` (None: the mission start is unknown) is
    late at simulation time `now_s` (slot length `slot_s`; all in s)."""
    return slot_end_s is not None and now_s > slot_end_s + LATE_PLAN_SLOTS * slot_s
