"""One time base: simulation-time sources and the one slot timeline (pure, no I/O).

Time sources (`SimTime`): `now_s()` in simulation seconds, non-decreasing, and `speed`
(simulation seconds per wall second, > 0). `WallTime` is the wall clock for real vehicles,
`FuncTime` adapts any clock function (e.g. an in-process `sim.clock.SimClock`). The clock fed by
the world's Zenoh `clock` messages is I/O and lives with the bridge
(`isac_mission.service.bridge.clock_time.ClockSimTime`).

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
from typing import Final, Protocol

EPS_S: Final = 1e-9
"""The one tolerance, s, of simulation-time comparisons (slot boundaries, holds, waits)."""

UNPACED_SPEED: Final = 1e6
"""`FuncTime.speed` of a clock running as fast as possible (speed inf, 0 or NaN)."""


def reached(now_s: float, t_s: float) -> bool:
    """True when simulation time `now_s` has reached `t_s` (within EPS_S), both in s."""
    return now_s + EPS_S >= t_s


class SimTime(Protocol):
    """A source of simulation time: `now_s()` (s, non-decreasing) and `speed` (simulation
    seconds per wall second, > 0)."""

    def now_s(self) -> float:
        """Current simulation time, s."""
        ...

    @property
    def speed(self) -> float:
        """Simulation seconds per wall second."""
        ...


class WallTime:
    """The wall clock as simulation time, for real vehicles: Unix seconds (anchored once to
    `time.time()` and advanced by the monotonic clock, so it never jumps), speed 1.

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


class FuncTime:
    """Simulation time from functions: `now()` in s, `speed()` (or a fixed number).

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
