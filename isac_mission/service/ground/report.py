"""What the ground loop reports: per-slot events, counters, and totals over the whole run."""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from isac_mission.records import SlotRecord


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
    not_ok: int = 0

    def add(self, record: SlotRecord) -> None:
        self.slots += 1
        self.pcrb_trace_sum += float(record.pcrb_trace)
        self.not_ok += record.status != "ok"
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
