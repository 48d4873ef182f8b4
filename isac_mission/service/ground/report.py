"""What the ground loop reports: per-slot events, counters, and totals over the whole run."""

from __future__ import annotations

import logging
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from isac_mission.records import SlotRecord
from isac_mission.wire import MAX_REASON_CHARS

log = logging.getLogger(__name__)


@dataclass
class SlotEvent:
    """What the loop reports after each slot (for progress displays and tests)."""

    record: SlotRecord
    position_error_m: float | None
    latency_s: float
    links: dict[int, str]


SLOTS_KEPT = 3600
"""Per-slot figures the ground loop keeps in memory (one simulated hour at dt = 1 s); the trace
keeps every slot, and `MissionTotals` sums the whole run."""


@dataclass
class MissionTotals:
    """Running sums over every slot of the run, for end-of-run figures that do not need the
    slots themselves (so that a long-lived service does not grow)."""

    slots: int = 0
    with_truth: int = 0
    position_sq_error_m2: float = 0.0
    velocity_sq_error_m2ps2: float = 0.0
    pcrb_trace_sum: float = 0.0
    statuses: Counter[str] = field(default_factory=Counter)
    """Slots by status (the records' `status`: ok, infeasible, operator hold, ...)."""
    fallbacks: Counter[str] = field(default_factory=Counter)
    """Slots whose method's answer was not flown, by kind (the records' `fallback`)."""

    def add(self, record: SlotRecord) -> None:
        self.slots += 1
        self.pcrb_trace_sum += float(record.pcrb_trace)
        self.statuses[record.status] += 1
        if record.fallback:
            self.fallbacks[record.fallback] += 1
        if record.target_true is not None:
            err = np.asarray(record.target_est) - np.asarray(record.target_true)
            self.with_truth += 1
            self.position_sq_error_m2 += float(np.sum(err[:2] ** 2))
            self.velocity_sq_error_m2ps2 += float(np.sum(err[2:] ** 2))


@dataclass
class GroundReport:
    """Counters and per-slot figures of one run of the loop: the last SLOTS_KEPT slots' records,
    planning latencies and detection times, and totals over the whole run."""

    counters: Counter[str] = field(default_factory=Counter)
    records: deque[SlotRecord] = field(default_factory=lambda: deque(maxlen=SLOTS_KEPT))
    latencies_s: deque[float] = field(default_factory=lambda: deque(maxlen=SLOTS_KEPT))
    last_detection_wall_s: dict[int, float] = field(default_factory=dict)
    """Slot -> wall time (time.monotonic) its last detection arrived (the last SLOTS_KEPT)."""
    last_error: str = ""
    totals: MissionTotals = field(default_factory=MissionTotals)

    def count_internal_error(self, err: Exception) -> None:
        """A bug in the loop: counted, kept as the last error, logged with its traceback (call
        from the `except` block)."""
        self.counters["internal errors"] += 1
        self.last_error = f"internal error: {type(err).__name__}: {err}"[:MAX_REASON_CHARS]
        log.exception("ground loop: internal error (the loop goes on)")

    def count_rejected(self, reason: str, err: Exception) -> None:
        """An invalid payload: counted under "rejected <reason>" (wire.rejection_reason), its
        message kept as the last error, and logged (the first few of each reason, then every
        100th: a flood of garbage must not turn into a flood of log lines)."""
        name = f"rejected {reason}"
        self.counters[name] += 1
        self.last_error = str(err)[:MAX_REASON_CHARS]
        n = self.counters[name]
        if n <= 5 or n % 100 == 0:
            log.warning("dropped message (%s #%d): %s", name, n, self.last_error)
