"""The tracks of a slot line (docs/trace.md): what every line carries whatever the number of
targets (`tracks_fields`, each track with its operator's priority when it is not 1), the whole
line of a tracker that may hold several tracks (`slot_fields`), what a live line adds so that a
restart continues after it (`resume_fields`, `priorities_field`, read back by `resume_point`,
`read_priorities`), and the tracks of any line read back (`TracksLine`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from isac_mission.errors import MessageError
from isac_mission.model.detections import UavReport
from isac_mission.records.fields import as_float, as_int, as_str, float_array, int_array
from isac_mission.records.jsonlines import dumps_line, loads_line, to_jsonable
from isac_mission.records.slot import MissionEnd, SlotRecord
from isac_mission.tracking.imm import N_STATE, ImmBelief
from isac_mission.tracking.multi_target import SavedTrack, TrackerState
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.priorities import DEFAULT_PRIORITY, Priorities, priority_problem
from isac_mission.tracking.tracker import LABELLED_TRACK_ID, TrackEstimate
from isac_mission.types import FloatArray, Gaussian, IntArray, SlotPlan


@dataclass(frozen=True)
class TracksSlot:
    """One slot of a tracker that may hold several tracks: plan (flown); uav_xy_m [M, 2] and
    bandwidth_share [M] where the reports were taken; truth [T, 4] every target's true state
    (NaN rows: not in the scene); reports [M] (with their true origins, for metrics); tracks:
    the tentative and confirmed tracks after the update; planned_for: the ID of the track the
    safety rule followed (0: none, the fleet held); tracker_state: what the tracker carries to
    the next slot (the live loop's, for `resume_fields`; None offline); start_xy [M, 2] m,
    start_velocity [M, 2] m/s: where and how fast the planner planned the slot from (None: not
    known, or no plan of the loop); priorities: the operator's priorities the slot's plan was
    made with (each track's `priority` in the line; None: every track 1); next_priorities: those
    the mission carries on with (the live loop's, for `resume_fields`; None offline)."""

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
    start_xy: FloatArray | None = field(default=None, compare=False)
    start_velocity: FloatArray | None = field(default=None, compare=False)
    priorities: Priorities | None = field(default=None, compare=False)
    next_priorities: Priorities | None = field(default=None, compare=False)


def end_line(end: MissionEnd) -> str:
    """The line that says how a live run ended (docs/trace.md, "End")."""
    return dumps_line(end.to_dict())


def tracks_fields(
    planned_for: int,
    truth: FloatArray,
    tracks: Sequence[TrackEstimate],
    reports: Sequence[UavReport],
    priorities: Priorities | None = None,
) -> dict[str, Any]:
    """The fields every slot line has, whatever the number of targets (docs/trace.md): the
    track the plan followed, the targets in the scene (truth [T, 4], NaN rows absent), every
    track after the update (with `priority`, the operator's priority the slot's plan was made
    with, when it is not 1: `priorities`, None for all 1), each UAV's report and its
    measurements' origins."""
    present = np.flatnonzero(np.all(np.isfinite(truth), axis=1))
    table = Priorities() if priorities is None else priorities
    return {
        "planned_for": planned_for,
        "targets": [{"index": int(t), "state": truth[t]} for t in present],
        "tracks": [
            {
                "id": t.track_id,
                "confirmed": t.confirmed,
                "x": t.belief.x,
                "P": t.belief.P,
                "pcrb_position_trace": float(np.trace(t.bound.C[:2, :2])),
                "weight": t.weight,
            }
            | _priority_entry(table[t.track_id])
            for t in tracks
        ],
        "measurements": [r.measurements for r in reports],
        "origins": [r.origin for r in reports],
    }


def _priority_entry(priority: float) -> dict[str, float]:
    """A track entry's `priority`: absent at the default (so a mission with none set writes the
    lines it always has)."""
    return {} if priority == DEFAULT_PRIORITY else {"priority": priority}


def priorities_field(priorities: Priorities | None) -> dict[str, Any]:
    """What a live line adds so that a restart goes on with the operator's priorities
    (docs/trace.md): `priorities`, every track whose priority is not 1 as {"id", "priority"},
    those of tracks yet to appear included; {} when there is none."""
    if priorities is None or not priorities.entries:
        return {}
    return {"priorities": priorities.to_json()}


def read_priorities(line: Mapping[str, Any]) -> Priorities:
    """The priorities a line's `priorities` field holds (`priorities_field`; absent: every track
    1); MessageError naming what is wrong."""
    value = line.get("priorities")
    if value is None:
        return Priorities()
    try:
        return Priorities.from_json(value)
    except ValueError as err:
        raise MessageError(f"slot {line.get('slot')}: {err}") from None


def slot_fields(o: TracksSlot, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One slot of a tracker of several tracks as a trace line's JSON object; `extra` adds
    fields (the live loop's latency, what a resume needs)."""
    rep = o.plan.report
    record: dict[str, Any] = {
        "slot": o.slot,
        "method": o.method,
        "status": rep.status,
        "fallback": rep.fallback,
        "solve_ms": 1e3 * rep.solve_s,
        "uav_xy": o.uav_xy_m,
        "eta": o.bandwidth_share,
        "assoc": o.plan.bs_of_uav,
    }
    record |= tracks_fields(o.planned_for, o.truth, o.tracks, o.reports, o.priorities)
    plan_fields: dict[str, Any] = {
        "reason": rep.reason or None,
        "plan_xy": None if rep.status in SKIPPED else o.plan.uav_xy_m,
        "plan_pcrb_trace": o.plan.pcrb_trace,
        "plan_velocity": o.plan.uav_velocity_mps,
        "plan_start_xy": o.start_xy,
        "plan_start_velocity": o.start_velocity,
    }
    record |= {k: v for k, v in plan_fields.items() if v is not None}
    return to_jsonable(record | dict(extra or {}))  # type: ignore[no-any-return]


def slot_line(o: TracksSlot, extra: Mapping[str, Any] | None = None) -> str:
    """`slot_fields` as a JSON line."""
    return dumps_line(slot_fields(o, extra))


SKIPPED = ("held", "unobserved")
"""The statuses of a slot the world ran without a plan of the ground loop (no plan_xy)."""


RESUME_FIELDS = ("plan_eta", "tracker")
"""The fields a live slot line adds for a restart (`resume_fields`)."""


def resume_fields(o: TracksSlot) -> dict[str, Any]:
    """The fields a live slot line adds so that a restart continues after it (docs/trace.md,
    "Lines of a tracker of several tracks"): `plan_eta`, the shares of the slot's plan (the next plan starts from
    them), and `tracker`, what the tracker carries to the next slot beside the `tracks` (each
    track's information J, hits and misses in a row, and pending refutation; the internal
    candidates; the next track ID), and the operator's priorities the mission goes on with
    (`priorities_field`, when any is not 1). {} without a tracker state (offline)."""
    st = o.tracker_state
    if st is None:
        return {}
    return priorities_field(o.next_priorities) | {
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
                    **_modes_field(t.modes),
                }
                for t in st.tracks
            ],
            "candidates": [{"x": c.x, "P": c.P} for c in st.candidates],
        },
    }


@dataclass(frozen=True)
class ResumePoint:
    """Where a multi-target mission goes on after a trace's slot line: slot, the tracker's
    state after it, plan_eta [M] the shares of its plan and assoc [M] its BSs (-1: none), and
    the operator's priorities it went on with (`read_priorities`)."""

    slot: int
    tracker: TrackerState
    plan_eta: FloatArray
    assoc: IntArray
    priorities: Priorities = field(default_factory=Priorities)


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
                _read_modes(k.get("modes"), f"{name}: tracker.tracks[{i}].modes"),
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
        read_priorities(line),
    )


def _modes_field(modes: ImmBelief | None) -> dict[str, Any]:
    """A track's IMM modes as its `tracker.tracks[i]` entry carries them (absent: an EKF's)."""
    if modes is None:
        return {}
    return {
        "modes": {
            "means": modes.means,
            "covariances": modes.covariances,
            "probabilities": modes.probabilities,
        }
    }


def _read_modes(obj: Any, name: str) -> ImmBelief | None:
    """The IMM modes of `_modes_field` (None when absent); MessageError naming what is wrong."""
    if obj is None:
        return None
    if not isinstance(obj, dict):
        raise MessageError(f"{name}: expected an object with means, covariances, probabilities")
    p = float_array(obj.get("probabilities"), f"{name}.probabilities", (None,))
    r = len(p)
    return ImmBelief(
        float_array(obj.get("means"), f"{name}.means", (r, N_STATE)),
        float_array(obj.get("covariances"), f"{name}.covariances", (r, N_STATE, N_STATE)),
        p,
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


@dataclass(frozen=True)
class TrackLine:
    """One track of a slot line as read: track_id, confirmed, x [4] (m, m/s), P [4, 4], the
    position part of its bound's trace (m^2), its association weight and its operator's
    priority the slot's plan was made with (1 when the line does not say)."""

    track_id: int
    confirmed: bool
    x: FloatArray
    P: FloatArray
    pcrb_position_trace: float
    weight: float
    priority: float = DEFAULT_PRIORITY


@dataclass(frozen=True)
class TracksLine:
    """The tracks of one slot line as read, whatever the trace's format (docs/trace.md): slot,
    method, status, fallback ("" when none); uav_xy [M, 2], eta [M], assoc [M]; planned_for;
    truth: target index -> its state [4] (the targets in the scene, when known); tracks;
    measurements [M] ([k, 2] each) and origins [M] ([k] each; both empty for a line that did
    not record them); line: the line's whole JSON object."""

    slot: int
    method: str
    status: str
    fallback: str
    uav_xy: FloatArray
    eta: FloatArray
    assoc: IntArray
    planned_for: int
    truth: dict[int, FloatArray]
    tracks: tuple[TrackLine, ...]
    measurements: tuple[FloatArray, ...]
    origins: tuple[IntArray, ...]
    line: dict[str, Any]

    @property
    def n_uavs(self) -> int:
        return int(self.uav_xy.shape[0])

    @classmethod
    def parse(cls, obj: Mapping[str, Any]) -> TracksLine:
        """The tracks of a line that records them (`tracks_fields`); MessageError naming the
        field at fault."""
        if not isinstance(obj, Mapping):
            raise MessageError(f"a slot line must be a JSON object (got {type(obj).__name__})")
        slot = as_int(obj.get("slot"), "slot")
        uav_xy = float_array(obj.get("uav_xy"), "uav_xy", (None, 2))
        M = len(uav_xy)
        tracks = obj.get("tracks")
        targets = obj.get("targets", [])
        if not isinstance(tracks, list) or not isinstance(targets, list):
            raise MessageError(f"slot {slot}: `tracks` and `targets` must be lists")
        parsed = []
        for i, t in enumerate(tracks):
            name = f"tracks[{i}]"
            if not isinstance(t, Mapping) or not isinstance(t.get("confirmed"), bool):
                raise MessageError(f"{name}: expected an object with id, confirmed, x, P")
            parsed.append(
                TrackLine(
                    as_int(t.get("id"), f"{name}.id"),
                    bool(t["confirmed"]),
                    float_array(t.get("x"), f"{name}.x", (4,)),
                    float_array(t.get("P"), f"{name}.P", (4, 4)),
                    as_float(t.get("pcrb_position_trace"), f"{name}.pcrb_position_trace"),
                    as_float(t.get("weight", float("nan")), f"{name}.weight"),
                    _priority(t, name),
                )
            )
        truth = {}
        for i, e in enumerate(targets):
            if not isinstance(e, Mapping):
                raise MessageError(f"targets[{i}]: expected an object with index and state")
            truth[as_int(e.get("index"), f"targets[{i}].index")] = float_array(
                e.get("state"), f"targets[{i}].state", (4,)
            )
        measurements = obj.get("measurements", [[] for _ in range(M)])
        origins = obj.get("origins", [[] for _ in range(M)])
        if not isinstance(measurements, list) or not isinstance(origins, list):
            raise MessageError(f"slot {slot}: `measurements` and `origins` must be lists")
        return cls(
            slot=slot,
            method=as_str(obj.get("method"), "method"),
            status=as_str(obj.get("status"), "status"),
            fallback=str(obj.get("fallback") or ""),
            uav_xy=uav_xy,
            eta=float_array(obj.get("eta"), "eta", (M,)),
            assoc=int_array(obj.get("assoc"), "assoc"),
            planned_for=as_int(obj.get("planned_for", 0), "planned_for"),
            truth=truth,
            tracks=tuple(parsed),
            measurements=tuple(
                float_array(z if z else np.zeros((0, 2)), f"measurements[{m}]", (None, 2))
                for m, z in enumerate(measurements)
            ),
            origins=tuple(
                np.asarray(int_array(o, f"origins[{m}]") if o else np.zeros(0), dtype=np.int64)
                for m, o in enumerate(origins)
            ),
            line=dict(obj),
        )

    def priorities(self) -> Priorities:
        """The priorities the line's tracks record (tracks not in the line: 1)."""
        return Priorities.of((t.track_id, t.priority) for t in self.tracks)

    @classmethod
    def of_labelled(cls, obj: Mapping[str, Any], rec: SlotRecord) -> TracksLine:
        """The tracks of a labelled line of version 1 (no `tracks`): its one track, ID 1,
        confirmed, from target_est, P and J; the target's truth when known."""
        bound = Bound.from_information(np.asarray(rec.J))
        measured = float(np.sum(np.isfinite(rec.r_diag[: rec.n_uavs])))
        track = TrackLine(
            LABELLED_TRACK_ID,
            True,
            np.asarray(rec.target_est),
            np.asarray(rec.P),
            bound.position_trace,
            measured,
        )
        truth = {} if rec.target_true is None else {0: np.asarray(rec.target_true)}
        empty = tuple(np.zeros((0, 2)) for _ in range(rec.n_uavs))
        return cls(
            slot=rec.slot,
            method=rec.method,
            status=rec.status,
            fallback=rec.fallback or "",
            uav_xy=rec.uav_xy_m,
            eta=rec.bandwidth_share,
            assoc=rec.assoc,
            planned_for=LABELLED_TRACK_ID,
            truth=truth,
            tracks=(track,),
            measurements=empty,
            origins=tuple(np.zeros(0, dtype=np.int64) for _ in range(rec.n_uavs)),
            line=dict(obj),
        )


def _priority(entry: Mapping[str, Any], name: str) -> float:
    """A track entry's `priority` (absent: 1); MessageError when it is not a priority."""
    value = entry.get("priority", DEFAULT_PRIORITY)
    track_id = entry.get("id")
    problem = priority_problem(track_id, value)
    if problem is not None:
        raise MessageError(f"{name}.priority: {problem}")
    return float(value)
