"""The multi-target trace (docs/trace.md, "Multi-target traces"): line 1 is
`{"format": TRACE_FORMAT, "config": {...}}`, every further line one slot (`slot_line`), and
live an `end` line where a run of the ground loop ended (`end_line`). The offline multi-target
loop and the live ground loop write the same lines.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from isac_mission.model.detections import UavReport
from isac_mission.records.jsonlines import dumps_line, to_jsonable
from isac_mission.records.slot import MissionEnd
from isac_mission.tracking.tracker import TrackEstimate
from isac_mission.types import FloatArray, SlotPlan

TRACE_FORMAT = "isac-mission multi-target trace 1"
"""The first line's `format` of a multi-target trace."""


@dataclass(frozen=True)
class MultiTargetSlot:
    """One slot: plan (flown); uav_xy_m [M, 2] and bandwidth_share [M] where the reports were
    taken; truth [T, 4] every target's true state (NaN rows: not in the scene); reports [M]
    (with their true origins, for metrics); tracks: the tentative and confirmed tracks after the
    update; planned_for: the ID of the track the safety rule followed (0: none, the fleet held)."""

    slot: int
    method: str
    plan: SlotPlan
    uav_xy_m: FloatArray
    bandwidth_share: FloatArray
    truth: FloatArray
    reports: tuple[UavReport, ...]
    tracks: tuple[TrackEstimate, ...]
    planned_for: int


def header_line(config: dict[str, Any]) -> str:
    """Line 1 of a multi-target trace: the format and the resolved configuration."""
    return dumps_line(to_jsonable({"format": TRACE_FORMAT, "config": config}))


def end_line(end: MissionEnd) -> str:
    """The line that says how a live run ended (as in a single-target trace: docs/trace.md)."""
    return dumps_line(end.to_dict())


def slot_line(o: MultiTargetSlot, extra: dict[str, Any] | None = None) -> str:
    """One slot of a multi-target trace as a JSON line; `extra` adds fields (the live loop's
    latency, counters)."""
    present = np.flatnonzero(np.all(np.isfinite(o.truth), axis=1))
    record: dict[str, Any] = {
        "slot": o.slot,
        "method": o.method,
        "status": o.plan.report.status,
        "fallback": o.plan.report.fallback,
        "solve_ms": 1e3 * o.plan.report.solve_s,
        "uav_xy": o.uav_xy_m,
        "eta": o.bandwidth_share,
        "assoc": o.plan.bs_of_uav,
        "planned_for": o.planned_for,
        "targets": [{"index": int(t), "state": o.truth[t]} for t in present],
        "tracks": [
            {
                "id": t.track_id,
                "confirmed": t.confirmed,
                "x": t.belief.x,
                "P": t.belief.P,
                "pcrb_position_trace": float(np.trace(t.bound.C[:2, :2])),
                "weight": t.weight,
            }
            for t in o.tracks
        ],
        "measurements": [r.measurements for r in o.reports],
        "origins": [r.origin for r in o.reports],
    }
    return dumps_line(to_jsonable(record | (extra or {})))
