"""The ground loop's trace file (docs/trace.md), its track message, and what it reports per slot.

The loop writes every slot through one `SlotOutput`, made for the scenario's tracker by
`slot_output`: the labelled target's trace (`records.TraceWriter`, `SlotRecord` lines, the
`track` message; a resume continues from the last complete slot's estimate, covariance and
bound) or the trace of tracks (`records/tracks.py` lines, the `track_set` message; a
resume restores the tracker from the last complete slot line). Both write and fsync slot by
slot, continue a resumed trace after its last complete slot (a torn last line is cut off), start
afresh when the file has no complete line, and end each run with an `end` line. Each track in a
line and in the track message carries the operator's priority (the line: its plan's; the
message: the one the mission goes on with), and a live line the whole table a resume continues
with (`records.tracks.priorities_field`).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import ConfigError, MessageError
from isac_mission.records import MissionEnd, SlotRecord, TraceWriter, read_trace
from isac_mission.records.progress import trace_progress
from isac_mission.records.tracks import (
    TracksSlot,
    config_differences,
    priorities_field,
    read_priorities,
    resume_fields,
    resume_point,
    tracks_fields,
)
from isac_mission.service.ground.mission import GroundSlot
from isac_mission.service.ground.report import SLOTS_KEPT, GroundReport, SlotEvent
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.tracking.cycle import TrackState
from isac_mission.tracking.factory import tracker_for
from isac_mission.tracking.pcrb import Bound
from isac_mission.tracking.priorities import Priorities
from isac_mission.tracking.tracker import LABELLED_TRACK_ID, Tracker
from isac_mission.types import FloatArray, Gaussian, IntArray
from isac_mission.wire import (
    DetectionMsg,
    DetectionSetMsg,
    Message,
    TrackEntry,
    TrackMsg,
    TrackSetMsg,
    TruthMsg,
    TruthSetMsg,
)

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ResumeFrom:
    """Where a resumed trace goes on: after `slot`, with the tracker's saved state (for
    `tracking/factory.restored_tracker`), and that slot's plan's shares eta [M] and BSs
    assoc [M], and the operator's priorities the mission went on with (the line's
    `priorities`: `MissionState.resumed`)."""

    slot: int
    saved: object
    eta: FloatArray
    assoc: IntArray
    priorities: Priorities = field(default_factory=Priorities)


class SlotOutput(Protocol):
    """What the bus carries for the scenario's tracker (the message types of a UAV's report and
    of the world's truth), and where each processed slot goes: the trace, the report, the track
    message."""

    last_traced: int

    @property
    def report_type(self) -> type[DetectionMsg] | type[DetectionSetMsg]:
        """The message type of a UAV's report."""
        ...

    @property
    def truth_type(self) -> type[TruthMsg] | type[TruthSetMsg]:
        """The message type of the world's truth."""
        ...

    """The last slot in the trace (a resumed trace's last slot before this run's)."""

    def open(self) -> ResumeFrom | None:
        """Create the trace, or (settings.resume) reopen it after its last complete slot;
        returns where a resume goes on (None: slot 1). ConfigError when it must not be
        continued."""
        ...

    def close(self, end: Callable[[int], MissionEnd]) -> None:
        """End the trace with the `end` line of the run (end(last traced slot))."""
        ...

    def track_message(self, g: GroundSlot, t_s: float) -> Message:
        """The slot's tracks as the bus carries them."""
        ...

    def complete(
        self, g: GroundSlot, extra: dict[str, Any], latency_s: float, links: dict[int, str]
    ) -> None:
        """Write the slot's line (with `extra` fields), keep it in the report and tell the
        caller's progress callback."""
        ...


def slot_output(
    s: Scenario,
    tracker: Tracker,
    settings: GroundSettings,
    report: GroundReport,
    on_slot: Callable[[SlotEvent], None] | None,
    on_tracks: Callable[[TracksSlot, float], None] | None,
) -> SlotOutput:
    """The output of the mission's tracker (module doc)."""
    if tracker.labels_reports:
        return RecordOutput(s, settings, report, on_slot)
    return TrackSetOutput(s, settings, on_tracks)


def live_trace_config(
    planning: Scenario, method: str, limits: Mapping[str, object]
) -> dict[str, object]:
    """The config line of a live trace: the planning scenario's config, its seed and the method,
    and `limits` over them (GroundSettings.trace_config: the vehicles' real limits beside the
    planner's, service/assembly.py `live_trace_limits`)."""
    return planning.trace_config() | {"seed": planning.seed, "method": method} | dict(limits)


class RecordOutput:
    """The labelled target's trace: one `SlotRecord` per slot (docs/trace.md)."""

    report_type = DetectionMsg
    truth_type = TruthMsg

    def __init__(
        self,
        s: Scenario,
        settings: GroundSettings,
        report: GroundReport,
        on_slot: Callable[[SlotEvent], None] | None,
    ) -> None:
        self.s, self.settings, self.report, self.on_slot = s, settings, report, on_slot
        self.writer: TraceWriter | None = None
        self.last_traced = 0

    def open(self) -> ResumeFrom | None:
        path = self.settings.trace_path
        if path is None:
            return None
        path.parent.mkdir(parents=True, exist_ok=True)
        if self.settings.resume and path.exists() and b"\n" not in path.read_bytes():
            # Killed before its config line was complete: no slot to lose, start afresh.
            log.warning("%s has no complete line; starting a new trace", path)
        elif self.settings.resume and path.exists():
            trace = read_trace(path)
            self.writer = TraceWriter.resume(path, fsync=True)
            if not trace.slots:
                return None
            last = trace.slots[-1]
            self.last_traced = last.slot
            belief = Gaussian(np.asarray(last.target_est), np.asarray(last.P))
            saved = TrackState(belief, Bound.from_information(np.asarray(last.J)))
            return ResumeFrom(
                last.slot,
                saved,
                np.asarray(last.bandwidth_share, dtype=float),
                np.asarray(last.assoc, dtype=np.int64),
                read_priorities({"slot": last.slot, **last.extra}),
            )
        config = live_trace_config(self.s, self.settings.method, self.settings.trace_config)
        self.writer = TraceWriter(path, config, fsync=True)
        return None

    def close(self, end: Callable[[int], MissionEnd]) -> None:
        if self.writer is not None:
            last = self.writer.last_record
            self.writer.write_end(end(0 if last is None else last.slot))
            self.writer.close()

    def track_message(self, g: GroundSlot, t_s: float) -> Message:
        (track,) = g.tracking.tracks
        return TrackMsg(
            slot=g.slot,
            t_s=t_s,
            x=track.belief.x,
            P=track.belief.P,
            J=track.bound.J,
            pcrb_trace=track.bound.trace,
            published_wall_s=time.time(),
            priority=g.priorities[LABELLED_TRACK_ID],
        )

    def complete(
        self, g: GroundSlot, extra: dict[str, Any], latency_s: float, links: dict[int, str]
    ) -> None:
        record = slot_record(g, extra)
        if self.writer is not None:
            self.writer.write_slot(record)
        self.last_traced = g.slot
        self.report.records.append(record)
        self.report.totals.add(record)
        if self.on_slot is not None:
            truth = record.target_true
            err = None
            if truth is not None:
                err = float(np.linalg.norm(np.asarray(record.target_est)[:2] - truth[:2]))
            self.on_slot(SlotEvent(record, err, latency_s, links))


def slot_record(g: GroundSlot, extra: Mapping[str, Any]) -> SlotRecord:
    """The labelled target's trace line of a slot (docs/trace.md), with `extra` fields."""
    (track,) = g.tracking.tracks
    (prediction,) = g.predictions
    pending, plan = g.pending, g.plan
    rep = plan.report
    bound = track.bound
    received = sum(
        1 for r in g.reports if len(r.measurements) and np.isfinite(r.measurements).all()
    )
    record = SlotRecord(
        slot=g.slot,
        method=g.method,
        status=rep.status,
        uav_xy_m=g.known_xy if pending.skipped else g.uav_xy,
        bandwidth_share=g.eta,
        assoc=g.assoc,
        target_true=g.truth[0] if g.truth_known else None,
        target_est=track.belief.x,
        target_pred=prediction.prediction.x,
        r_diag=_labelled(track.variances),
        pcrb_trace=bound.trace,
        solve_ms=rep.solve_s * 1e3,
        P=track.belief.P,
        J=bound.J,
        plan_xy=None if pending.skipped else plan.uav_xy_m,
        plan_pcrb_trace=plan.pcrb_trace,
        plan_velocity=plan.uav_velocity_mps,
        reason=rep.reason or None,
        fallback=rep.fallback or None,
        plan_start_xy=pending.start_xy,
        plan_start_velocity=pending.start_velocity,
        extra={
            "pcrb_pos": bound.position_trace,
            "pcrb_vel": bound.velocity_trace,
            "received": received,
        }
        | ({"planned_around": list(pending.planned_around)} if pending.planned_around else {})
        | dict(extra)
        | priorities_field(g.priorities)
        | tracks_fields(g.planned_for, g.truth, g.tracking.tracks, g.reports, g.pending.priorities),
    )
    return record


def _labelled(variances: FloatArray | None) -> FloatArray:
    if variances is None:
        raise ValueError("the labelled target's track carries its measurement variances")
    return variances


def track_set_slot(g: GroundSlot) -> TracksSlot:
    """The trace-of-tracks line of a slot (records/tracks.py): `eta` 0 for a UAV whose
    report did not arrive (the tracker took nothing from it); a skipped slot's positions where
    its reports said (NaN: none); the priorities its plan was made with, and those the mission
    goes on with (for a resume)."""
    arrived = np.isfinite(g.known_xy[:, 0])
    return TracksSlot(
        g.slot,
        g.method,
        g.plan,
        g.known_xy if g.pending.skipped else g.uav_xy,
        np.where(arrived, g.eta, 0.0),
        g.truth,
        g.reports,
        g.tracking.tracks,
        g.planned_for,
        g.saved,  # type: ignore[arg-type]  # the tracker of tracks' TrackerState
        g.pending.start_xy,
        g.pending.start_velocity,
        g.pending.priorities,
        g.priorities,
    )


class TrackSetOutput:
    """The trace of tracks (docs/trace.md, "Lines of a tracker of several tracks")."""

    report_type = DetectionSetMsg
    truth_type = TruthSetMsg

    def __init__(
        self,
        s: Scenario,
        settings: GroundSettings,
        on_tracks: Callable[[TracksSlot, float], None] | None,
    ) -> None:
        self.s, self.settings, self.on_tracks = s, settings, on_tracks
        self.slots: deque[TracksSlot] = deque(maxlen=SLOTS_KEPT)
        """The last SLOTS_KEPT slots (the trace keeps every one)."""
        self.writer: TraceWriter | None = None
        self.last_traced = 0

    def config(self) -> dict[str, object]:
        """The config line this output writes (docs/trace.md)."""
        return live_trace_config(self.s, self.settings.method, self.settings.trace_config)

    def open(self) -> ResumeFrom | None:
        path = self.settings.trace_path
        if path is None:
            return None
        path.parent.mkdir(parents=True, exist_ok=True)
        if self.settings.resume and path.exists() and b"\n" in path.read_bytes():
            refusal = track_set_refusal(path, self.config(), self.s.N)
            if refusal is not None:
                raise ConfigError(f"--resume: {refusal}")
            last_line = trace_progress(path).last_line
            self.writer = TraceWriter.resume(path, fsync=True)
            if last_line is None:
                return None
            point = resume_point(last_line)
            self.last_traced = point.slot
            return ResumeFrom(
                point.slot, point.tracker, point.plan_eta, point.assoc, point.priorities
            )
        if self.settings.resume and path.exists():
            log.warning("%s has no complete line; starting a new trace", path)
        self.writer = TraceWriter(path, self.config(), fsync=True)
        return None

    def close(self, end: Callable[[int], MissionEnd]) -> None:
        if self.writer is not None:
            self.writer.write_end(end(self.writer.last_slot))
            self.writer.close()

    def track_message(self, g: GroundSlot, t_s: float) -> Message:
        entries = tuple(
            TrackEntry(
                track_id=t.track_id,
                confirmed=t.confirmed,
                x=t.belief.x,
                P=t.belief.P,
                pcrb_position_trace=float(np.trace(t.bound.C[:2, :2])),
                priority=g.priorities[t.track_id],
            )
            for t in g.tracking.tracks
        )
        return TrackSetMsg(slot=g.slot, t_s=t_s, tracks=entries, published_wall_s=time.time())

    def complete(
        self, g: GroundSlot, extra: dict[str, Any], latency_s: float, links: dict[int, str]
    ) -> None:
        slot = track_set_slot(g)
        around = g.pending.planned_around
        fields = (
            dict(extra) | ({"planned_around": list(around)} if around else {}) | resume_fields(slot)
        )
        if self.writer is not None:
            self.writer.write_slot(slot, fields)
        self.last_traced = g.slot
        self.slots.append(slot)
        if self.on_tracks is not None:
            self.on_tracks(slot, latency_s)


def resume_refusal(s: Scenario, path: Path, config: Mapping[str, object]) -> str | None:
    """Why the trace at `path` must not be continued by the mission of `s` that writes `config`
    as its config line (None: it may). A labelled target's trace is continued from its last
    complete slot (`RecordOutput.open`); a trace of tracks is refused as `track_set_refusal`
    says."""
    return None if tracker_for(s).labels_reports else track_set_refusal(path, config, s.N)


def track_set_refusal(path: Path, config: Mapping[str, object], n_slots: int) -> str | None:
    """Why the trace of tracks at `path` must not be continued by a mission that writes
    `config` as its config line (None: it may): it does not read, it is a single-target trace,
    it is complete (slot N = n_slots traced), it is another mission's, method's or config's, or
    its last slot line lacks what a restart needs (a trace written before resume existed).
    Reads the file, never writes it."""
    try:
        progress = trace_progress(path)
    except MessageError as err:
        return f"cannot continue {path}: {err}"
    if not progress.config:
        return None  # killed before its config line was complete: a new trace is started
    if progress.labelled and progress.slots:
        return f"{path} is a single-target trace, not a multi-target mission's"
    if progress.last_slot >= n_slots:
        return (
            f"the trace is complete: {progress.last_slot}/{n_slots} slots in {path}; nothing "
            "to resume (start a new mission without --resume, or in another --out)"
        )
    fresh = "start a new mission without --resume, or in another --out"
    theirs = progress.config
    for key, what in (("mission_id", "mission"), ("method", "method")):
        if theirs.get(key) != config.get(key):
            return (
                f"{path} is a trace of {what} {theirs.get(key)!r}, not {config.get(key)!r}; "
                + fresh
            )
    if progress.last_line is not None:
        try:
            resume_point(progress.last_line)
        except MessageError as err:
            return f"cannot continue {path}: {err}"
    differ = config_differences(theirs, config)
    if differ:
        shown = ", ".join(differ[:6]) + (f" and {len(differ) - 6} more" if len(differ) > 6 else "")
        return f"{path} was flown with another configuration (it differs in {shown}); {fresh}"
    return None
