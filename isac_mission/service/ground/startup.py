"""When the ground loop may plan: after its start, a resume, or a stall of its own process.

The loop plans only from where the vehicles are. With `wait_for_telemetry` (the live service,
whose bridges publish telemetry; a loop fed by a world alone has none to wait for),
`PlanningGate` starts closed: the loop plans
nothing (slot 1 at a start, slot L+1 on a resume) until every vehicle has reported telemetry
over a live link, fresh at the world's time and not excluded (exclusion.py); after
`startup_wait_s` of wall time without that, it plans the vehicles that have and plans around
the rest (excluded: "no telemetry"). A stall of the loop's own process (SIGSTOP, an overloaded
host: no wall tick for `stall_gap_s`) closes the gate again: the vehicles may have taken their
offboard-loss hold meanwhile, so the loop waits for telemetry that arrived at least
`stall_settle_s` after it woke (the backlog drained), and a plan made before the stall is not
published after it.

When the gate opens, every slot the world has already run without a plan from this loop (the
slots up to the world's clock) is traced without one (`MissionState.skip`): `held` when its reports
arrived (they carry where the vehicles really were), `unobserved` when none did (positions
unknown: null, prediction only). Never a plan's positions as a record of where the vehicles were.
Times: wall seconds from time.monotonic; simulation seconds from the world's clock.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from isac_mission.service.ground.exclusion import VehicleWatch
from isac_mission.service.ground.settings import GroundSettings

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GateWait:
    """One closing of the gate: why, and how long (wall s) the loop waited before planning."""

    reason: str
    waited_s: float
    planned: tuple[int, ...]
    """The vehicles planned when it opened (the others were excluded)."""


@dataclass
class PlanningGate:
    """Closed at the start and after a stall; `try_open` opens it (see the module doc)."""

    n_uavs: int
    settings: GroundSettings
    wall: Callable[[], float] = time.monotonic
    closed: bool = True
    reason: str = "start"
    since_wall_s: float = field(default=0.0)
    fresh_after_wall_s: float = 0.0
    last_tick_wall_s: float | None = None
    """Wall time of the loop's last tick (None before the first: no stall before it runs)."""
    waits: list[GateWait] = field(default_factory=list)
    stalls_s: list[float] = field(default_factory=list)
    """Wall length of every stall noticed (s)."""
    _told_timeout: bool = False
    _first_try_wall_s: float | None = None

    def __post_init__(self) -> None:
        now = self.wall()
        self.since_wall_s = self.fresh_after_wall_s = now
        self.closed = self.settings.wait_for_telemetry

    def tick(self) -> float | None:
        """Note that the loop runs now; returns the stall (wall s) when the previous tick was more
        than `stall_gap_s` ago, and closes the gate (None otherwise)."""
        now = self.wall()
        last, self.last_tick_wall_s = self.last_tick_wall_s, now
        gap = 0.0 if last is None else now - last
        if gap <= self.settings.stall_gap_s:
            return None
        self.stalls_s.append(gap)
        log.warning("ground loop stalled for %.1f s (wall)", gap)
        self.close(f"stall of {gap:.1f} s", self.settings.stall_settle_s)
        return gap

    def close(self, reason: str, settle_s: float = 0.0) -> None:
        """Plan nothing until `try_open`; telemetry counts from `settle_s` wall s from now.
        Nothing happens without `wait_for_telemetry` (no telemetry to wait for)."""
        if not self.settings.wait_for_telemetry:
            return
        now = self.wall()
        self.closed, self.reason, self._told_timeout = True, reason, False
        self._first_try_wall_s = None
        self.since_wall_s, self.fresh_after_wall_s = now, now + settle_s

    def try_open(self, vehicles: VehicleWatch, t_s: float) -> bool:
        """Open when every vehicle (after a stall: every vehicle not excluded) is ready at
        simulation time t_s, or `startup_wait_s` after the first call (the loop calls once the
        mission has started) with at least one ready (the others are excluded). True when open."""
        if not self.closed:
            return True
        now = self.wall()
        if self._first_try_wall_s is None:
            self._first_try_wall_s = now
        ready = [m for m in range(self.n_uavs) if vehicles.ready(m, t_s, self.fresh_after_wall_s)]
        wanted = [
            m
            for m in range(self.n_uavs)
            if self.reason in ("start", "resume") or m not in vehicles.excluded
        ]
        waited = now - self._first_try_wall_s
        timed_out = waited > self.settings.startup_wait_s
        if not ready or not (set(wanted) <= set(ready) or timed_out):
            if timed_out and not self._told_timeout:
                self._told_timeout = True
                log.warning("no vehicle has reported after %.0f s; still waiting", waited)
            return False
        for m in sorted(set(range(self.n_uavs)) - set(ready)):
            vehicles.exclude(m, f"no fresh telemetry within {self.settings.startup_wait_s:g} s")
        self.closed = False
        self.waits.append(GateWait(self.reason, waited, tuple(ready)))
        # A start is no "again" (and a vehicle that did not report was warned of as excluded):
        # only a reopening after a stall or a resume is news.
        if self.reason != "start":
            log.warning(
                "%s: planning again after %.2f s of wall time, vehicles %s reported",
                self.reason,
                waited,
                ready,
            )
        return True
