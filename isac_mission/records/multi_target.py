"""The multi-target trace (docs/trace.md, "Multi-target traces"): line 1 is
`{"format": TRACE_FORMAT, "config": {...}}`, every further line one slot (`slot_line`), and
live an `end` line where a run of the ground loop ended (`end_line`). The offline multi-target
loop and the live ground loop write the same lines; the live one adds what a restart needs to
continue after the line (`resume_fields`, read back by `resume_point`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from isac_mission.errors import MessageError
from isac_mission.model.detections import UavReport
from isac_mission.records.fields import as_int, float_array, int_array
from isac_mission.records.jsonlines import dumps_line, loads_line, to_jsonable
from isac_mission.records.slot import MissionEnd
from isac_mission.tracking.multi_target import SavedTrack, TrackerState
from isac_mission.tracking.tracker import TrackEstimate
from isac_mission.types import FloatArray, Gaussian, IntArray, SlotPlan

TRACE_FORMAT = "isac-mission multi-target trace 1"
"""The first line's `format` of a multi-target trace."""


@dataclass(frozen=True)
class MultiTargetSlot:
    """One slot: plan (flown); uav_xy_m [M, 2] and bandwidth_share [M] where the reports were
    taken; truth [T, 4] every target's true state (NaN rows: not in the scene); reports [M]
    (with their true origins, for metrics); tracks: the tentative and confirmed tracks after the
    update; planned_for: the ID of the track the safety rule followed (0: none, the fleet held);
    tracker_state: what the tracker carries to the next slot (the live loop's, for
    `resume_fields`; None offline)."""

    slot: int
    method: str
    plan: SlotPlan
    uav_xy_m: FloatArray
    bandwidth_share: FloatArray
    truth: FloatArray
    reports: tuple[UavReport, ...]
    tracks: tuple[TrackEstimate, ...]
    planned_for: int
    tracker_state: TrackerState | None = field(default=None, compare=False)


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


RESUME_FIELDS = ("plan_eta", "tracker")
"""The fields a live slot line adds for a restart (`resume_fields`)."""


def resume_fields(o: MultiTargetSlot) -> dict[str, Any]:
    """The fields a live slot line adds so that a restart continues after it (docs/trace.md,
    "Multi-target traces"): `plan_eta`, the shares of the slot's plan (the next plan starts from
    them), and `tracker`, what the tracker carries to the next slot beside the `tracks` (each
    track's information J, hits and misses in a row, and pending refutation; the internal
    candidates; the next track ID). {} without a tracker state (offline)."""
    st = o.tracker_state
    if st is None:
        return {}
    return {
        "plan_eta": o.plan.bandwidth_share,
        "tracker": {
            "next_id": st.next_id,
            "tracks": [
                {
                    "id": t.track_id,
                    "J": t.information,
                    "hits": list(t.hits),
                    "misses": t.misses_in_row,
                    "refuted": None if t.refuted is None else {"x": t.refuted.x, "P": t.refuted.P},
                }
                for t in st.tracks
            ],
            "candidates": [{"x": c.x, "P": c.P} for c in st.candidates],
        },
    }


@dataclass(frozen=True)
class ResumePoint:
    """Where a multi-target mission goes on after a trace's slot line: slot, the tracker's
    state after it, plan_eta [M] the shares of its plan and assoc [M] its BSs (-1: none)."""

    slot: int
    tracker: TrackerState
    plan_eta: FloatArray
    assoc: IntArray


def resume_point(line: Mapping[str, Any]) -> ResumePoint:
    """The ResumePoint of a parsed slot line; MessageError naming what the line lacks or what is
    wrong (a line written before live traces carried `plan_eta` and `tracker` cannot be
    continued)."""
    slot = as_int(line.get("slot"), "slot")
    missing = [k for k in RESUME_FIELDS if k not in line]
    if missing:
        raise MessageError(
            f"slot {slot}'s line has no {' or '.join(f'`{k}`' for k in missing)}: a trace "
            "written before multi-target traces could be resumed cannot be continued"
        )
    saved = line["tracker"]
    tracks = line.get("tracks")
    if not isinstance(saved, dict) or not isinstance(tracks, list):
        raise MessageError(f"slot {slot}: `tracker` must be an object and `tracks` a list")
    kept = saved.get("tracks")
    if not isinstance(kept, list) or len(kept) != len(tracks):
        raise MessageError(f"slot {slot}: `tracker.tracks` must have one entry per track")
    restored = []
    for i, (t, k) in enumerate(zip(tracks, kept, strict=True)):
        name = f"slot {slot}: tracks[{i}]"
        if not isinstance(t, dict) or not isinstance(k, dict):
            raise MessageError(f"{name}: expected objects")
        track_id = as_int(t.get("id"), f"{name}.id")
        if as_int(k.get("id"), f"{name}: tracker.tracks[{i}].id") != track_id:
            raise MessageError(f"{name}: tracker.tracks[{i}] is another track's")
        hits = k.get("hits")
        if not isinstance(hits, list) or not all(isinstance(h, bool) for h in hits):
            raise MessageError(f"{name}: tracker.tracks[{i}].hits: expected true/false values")
        confirmed = t.get("confirmed")
        if not isinstance(confirmed, bool):
            raise MessageError(f"{name}.confirmed: expected true or false")
        refuted = k.get("refuted")
        restored.append(
            SavedTrack(
                track_id,
                confirmed,
                _belief(t, name),
                float_array(k.get("J"), f"{name}: tracker.tracks[{i}].J", (4, 4)),
                tuple(hits),
                as_int(k.get("misses"), f"{name}: tracker.tracks[{i}].misses"),
                None if refuted is None else _belief(refuted, f"{name}: refuted"),
            )
        )
    candidates = saved.get("candidates")
    if not isinstance(candidates, list):
        raise MessageError(f"slot {slot}: `tracker.candidates` must be a list")
    return ResumePoint(
        slot,
        TrackerState(
            tuple(restored),
            tuple(_belief(c, f"slot {slot}: candidates[{j}]") for j, c in enumerate(candidates)),
            as_int(saved.get("next_id"), f"slot {slot}: tracker.next_id"),
        ),
        float_array(line["plan_eta"], f"slot {slot}: plan_eta", (None,)),
        int_array(line.get("assoc"), f"slot {slot}: assoc"),
    )


def _belief(obj: Any, name: str) -> Gaussian:
    if not isinstance(obj, dict):
        raise MessageError(f"{name}: expected an object with x and P")
    return Gaussian(
        x=float_array(obj.get("x"), f"{name}.x", (4,)),
        P=float_array(obj.get("P"), f"{name}.P", (4, 4)),
    )


def config_differences(trace: Mapping[str, Any], mine: Mapping[str, Any]) -> list[str]:
    """The config keys (nested ones dotted) in which a trace's config line and `mine` (the
    config this run would write) differ, `mine` taken as written (strict JSON, read back)."""
    written = loads_line(dumps_line(to_jsonable(dict(mine))))
    return _differences(dict(trace), written, "")


def _differences(a: dict[str, Any], b: dict[str, Any], prefix: str) -> list[str]:
    out: list[str] = []
    for key in sorted(set(a) | set(b)):
        va, vb = a.get(key), b.get(key)
        if isinstance(va, dict) and isinstance(vb, dict):
            out += _differences(va, vb, f"{prefix}{key}.")
        elif key not in a or key not in b or va != vb:
            out.append(f"{prefix}{key}")
    return out
