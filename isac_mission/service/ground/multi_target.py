"""The ground loop of a multi-target mission: unlabelled reports -> tracks -> plan, over Zenoh.

The same slot recursion as the offline multi-target loop (experiment/multi_target_loop.py),
split where the live service waits for the network: after slot n's reports are in (or waited
for: assembler.py), every track is updated (tracking/multi_target.py), the tracks go out as a
`track_set`, the slot's trace line is written and flushed (records/multi_target.py), and slot
n + 1 is planned for the predicted tracks (planning/multi_target.plan_tracks) on the planner
thread within the time budget. The world's `truth_set` goes into the trace only (with the
measurements' origins, for the metrics); the tracker never reads it.

What the single-target loop does and this one does too: plans wait for fresh telemetry at the
start (startup.py's gate), a plan over budget is a hold (status "timeout"), a solver error flies
the communication-optimal plan (a hold only if that fails too: planning/fleet.py
`after_solver_error`), a plan the bridges would drop is marked "late" (BusLoop._marked_if_late),
a plan made before a stall is dropped and made again, invalid payloads are counted and dropped,
operators' requests are answered (control.py; `set` changes R_th from the next slot), a vehicle
out of the plan holds and the others plan around it (planning/fleet.py's kits and widening), and
`--resume` continues a trace after its last complete slot: the tracker restored from that line
(records/multi_target.py `resume_point`), the gate closed until the vehicles report, the slots
the world ran meanwhile traced `held` or `unobserved` (docs/service.md, "Several intruders").
"""

from __future__ import annotations

import asyncio
import logging
import os
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO

import numpy as np

from isac_mission.bus import ZenohBus
from isac_mission.config import Scenario
from isac_mission.errors import ConfigError, MessageError
from isac_mission.model.detections import UavReport
from isac_mission.planning.fallback import NO_BS, OPERATOR_HOLD
from isac_mission.planning.fleet import (
    OPERATOR_HOLD_REASON,
    SOLVER_ERROR,
    KitCache,
    active_part,
    after_solver_error,
    widen_plan,
)
from isac_mission.planning.multi_target import (
    KEEP_OUT_CAPACITY,
    check_multi_target_method,
    hold_without_track,
    multi_target_kit,
    plan_tracks,
)
from isac_mission.planning.slot import Method, SolverKit
from isac_mission.records.multi_target import (
    MultiTargetSlot,
    ResumePoint,
    config_differences,
    end_line,
    header_line,
    resume_fields,
    resume_point,
    slot_line,
)
from isac_mission.records.progress import trace_progress
from isac_mission.service.ground.assembler import DetectionAssembler
from isac_mission.service.ground.bus_loop import BusLoop
from isac_mission.service.ground.mission import leg_start_state
from isac_mission.service.ground.planner_thread import consume_result, in_daemon_thread
from isac_mission.service.ground.report import SLOTS_KEPT
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.startup import HELD, UNOBSERVED
from isac_mission.timebase import SlotTimeline
from isac_mission.tracking.multi_target import MultiTargetTracker, TrackerSettings
from isac_mission.tracking.tracker import TrackPrediction
from isac_mission.types import FloatArray, Gaussian, IntArray, SlotPlan, SolveReport
from isac_mission.wire import (
    DetectionSetMsg,
    PlanMsg,
    TrackEntry,
    TrackSetMsg,
    TruthSetMsg,
    decode,
    encode,
)

log = logging.getLogger(__name__)

NO_ORIGIN = -2
"""A measurement's origin when the world's truth did not say (no truth_set for the slot)."""


@dataclass(frozen=True)
class PendingPlan:
    """The plan of slot `slot`, made for the tracks' predictions, and the ID of the track its
    safety rule followed (0: the fleet held)."""

    slot: int
    plan: SlotPlan
    planned_for: int
    start_xy: FloatArray
    """[M, 2] m: where it was planned from."""


class MultiTargetMission:
    """The tracks after the last processed slot and the plan of the next (no I/O).

    initial_errors [T, 4]: added to each known target's initial state to start its track (the
    offline twin's x_hat - x; None: start at the configured state, the cue)."""

    def __init__(
        self,
        s: Scenario,
        kit: SolverKit,
        method: Method,
        initial_errors: FloatArray | None = None,
    ) -> None:
        check_multi_target_method(method)
        if s.detection is None:
            raise ConfigError(f"{s.mission_id}: a multi-target mission needs a detection model")
        self._scenario = s
        self.kit = kit
        self.kits = KitCache(kit, method, KEEP_OUT_CAPACITY)
        """Kits for the fleet without the excluded vehicles (their positions keep-out points
        beside the tracks')."""
        self.method: Method = method
        self.tracker = MultiTargetTracker(TrackerSettings.from_scenario(s))
        self.initial_errors = initial_errors
        self.slot = 0
        self.eta: FloatArray = np.full(s.M, 1.0 / s.M)
        self.assoc: IntArray | None = None
        self.pending: PendingPlan | None = None
        self.last_plan: SlotPlan | None = None
        self.last_excluded: tuple[int, ...] = ()
        """The vehicles the last committed plan left out (its prev_plan role needs the same)."""
        self._predicted: tuple[TrackPrediction, ...] | None = None
        """The tracks predicted to slot + 1 (None: not yet): a plan dropped after a stall is
        made again from the same prediction."""
        self._started_at: int | None = None
        """The slot after which the known targets' tracks were last started."""

    @classmethod
    def resumed(
        cls,
        s: Scenario,
        kit: SolverKit,
        method: Method,
        point: ResumePoint,
        initial_errors: FloatArray | None = None,
    ) -> MultiTargetMission:
        """Continue after a trace's slot line (`resume_point`): its tracker (tracks, IDs,
        candidates, next ID), its plan's shares and BSs; no last plan (the vehicles were not
        flying this loop's plan). ValueError when the line does not fit `s`."""
        mission = cls(s, kit, method, initial_errors)
        if point.slot >= s.N:
            raise ValueError(f"slot {point.slot} is the mission's last ({s.N}): nothing to resume")
        if point.plan_eta.shape != (s.M,) or point.assoc.shape != (s.M,):
            raise ValueError(f"slot {point.slot}'s line is not for {s.M} UAVs")
        mission.tracker = MultiTargetTracker.restored(
            TrackerSettings.from_scenario(s), point.tracker
        )
        mission.slot = point.slot
        mission.eta = np.array(point.plan_eta, dtype=float)
        mission.assoc = np.array(point.assoc, dtype=np.int64)
        return mission

    @property
    def scenario(self) -> Scenario:
        return self._scenario

    @property
    def done(self) -> bool:
        return self.slot >= self._scenario.N

    def set_scenario(self, s: Scenario) -> None:
        """Plan from now on with `s` (an operator's new R_th); same M and geometry."""
        if s.M != self._scenario.M:
            raise ValueError(f"the new scenario has M = {s.M}, the mission {self._scenario.M}")
        self._scenario = s
        self.renew_kits()

    def renew_kits(self) -> None:
        """Plan on fresh kits, for the current scenario, from now on (a timed-out planner
        thread keeps the old); the IPOPT problems, the solve lock and the compiled cache are
        kept (SolverKit.renewed)."""
        self.kit = self.kit.renewed(self._scenario)
        self.kits = KitCache(self.kit, self.method, KEEP_OUT_CAPACITY)

    def start_known_tracks(self) -> None:
        """Start a confirmed track for every known target that enters at the current slot
        (the offline loop's rule: before slot n + 1 is predicted, those of first slot n)."""
        if self._started_at == self.slot:
            return  # once per slot (a plan dropped after a stall is made again)
        self._started_at = self.slot
        s = self._scenario
        for t, spec in enumerate(s.targets):
            if spec.prior_known and spec.first_slot == self.slot:
                x = np.array(spec.x0, dtype=np.float64)
                if self.initial_errors is not None:
                    x = x + self.initial_errors[t]
                self.tracker.add_confirmed(Gaussian(x=x, P=s.P0.copy()))

    def predict(self) -> tuple[TrackPrediction, ...]:
        """Every track predicted to slot + 1 (before planning it); the tracker predicts once
        per slot, a second call returns the same predictions."""
        if self._predicted is None:
            self._predicted = self.tracker.predict()
        return self._predicted

    def plan(
        self,
        predictions: tuple[TrackPrediction, ...],
        uav_xy: FloatArray,
        uav_v: FloatArray | None,
        excluded: tuple[int, ...],
        operator_held: tuple[int, ...] = (),
        method: Method | None = None,
    ) -> tuple[int, SlotPlan]:
        """(the ID of the track planned around, the plan of slot + 1): thread-safe (touches only
        its arguments and the kits). The `excluded` vehicles (sorted) are left out: the others
        are planned with them as keep-out points (planning/fleet.py), and they hold; when
        every one of them is `operator_held` (an operator's hold or land), the slot's status is
        `operator hold`. method: the planning method (None: the mission's; "comm" after a
        planner error)."""
        s = self._scenario
        method = self.method if method is None else method
        prev = self.last_plan if self.last_excluded == excluded else None
        if not excluded:
            planned = plan_tracks(
                s, method, self.kit, predictions, uav_xy, self.eta, self.assoc, uav_v, prev
            )
            return planned.planned_for, planned.plan
        active = tuple(m for m in range(s.M) if m not in excluded)
        if not active:
            # Nobody is served: every share 0, no BS (planning/fallback.hold_plan's rule).
            hold = hold_without_track(s, uav_xy, np.zeros(s.M), np.full(s.M, NO_BS))
            if set(excluded) <= set(operator_held):
                return 0, _with_status(hold, OPERATOR_HOLD, OPERATOR_HOLD_REASON)
            return 0, _with_status(hold, "no vehicles", "hold: every vehicle is excluded")
        idx = list(active)
        kit = self.kits.for_active(active)
        eta = self.eta[idx]
        eta = eta / eta.sum() if eta.sum() > 0 else np.full(len(idx), 1.0 / len(idx))
        assoc = None if self.assoc is None else self.assoc[idx]
        if assoc is not None and np.any(assoc < 0):
            assoc = None
        planned = plan_tracks(
            kit.scenario,
            method,
            kit,
            predictions,
            uav_xy[idx],
            eta,
            assoc,
            None if uav_v is None else uav_v[idx],
            None if prev is None else active_part(prev, active),
            extra_keep_out_xy=uav_xy[list(excluded)],
        )
        return planned.planned_for, widen_plan(planned.plan, uav_xy, excluded)

    def commit(
        self,
        slot: int,
        planned_for: int,
        plan: SlotPlan,
        start_xy: FloatArray,
        excluded: tuple[int, ...] = (),
    ) -> None:
        """Adopt `plan` as the plan of slot `slot` = slot + 1, made without the `excluded`
        vehicles."""
        if slot != self.slot + 1:
            raise ValueError(f"plan for slot {slot}, but the next slot is {self.slot + 1}")
        self.pending = PendingPlan(slot, plan, planned_for, start_xy)
        self.last_excluded = excluded

    def process(
        self,
        n: int,
        msgs: dict[int, DetectionSetMsg],
        truth: TruthSetMsg | None,
        fallback_xy: FloatArray,
    ) -> MultiTargetSlot:
        """Fold in slot n's reports (a UAV whose report did not arrive contributes nothing;
        fallback_xy [M, 2] is where it was) and advance to slot n."""
        pending = self.pending
        if pending is None or n != pending.slot:
            raise ValueError(f"slot {n} is not the planned slot {self.slot + 1}")
        s = self._scenario
        eta = pending.plan.bandwidth_share.copy()
        uav_xy = np.array(fallback_xy, dtype=float)
        measurements: list[FloatArray] = []
        for m in range(s.M):
            msg = msgs.get(m)
            if msg is None:
                eta[m] = 0.0  # nothing arrived: the tracker treats the UAV as not sensing
                measurements.append(np.zeros((0, 2)))
                continue
            eta[m] = msg.bandwidth_share
            uav_xy[m] = msg.uav_xy_m
            measurements.append(msg.measurements)
        update = self.tracker.update(measurements, uav_xy, eta, self.kit.sensing)
        saved = self.tracker.saved()
        reports = tuple(
            UavReport(z, _origins(truth, m, len(z))) for m, z in enumerate(measurements)
        )
        T = len(s.targets)
        states = np.full((T, 4), np.nan) if truth is None else truth.states
        self.slot = n
        self.eta, self.assoc = pending.plan.bandwidth_share, pending.plan.bs_of_uav
        self.last_plan = pending.plan
        self.pending = None
        self._predicted = None
        return MultiTargetSlot(
            n,
            self.method,
            pending.plan,
            uav_xy,
            eta,
            states,
            reports,
            update.tracks,
            pending.planned_for,
            saved,
        )

    def skip(
        self,
        n: int,
        msgs: dict[int, DetectionSetMsg],
        truth: TruthSetMsg | None,
        compute_xy: FloatArray,
        why: str,
    ) -> MultiTargetSlot:
        """Slot n = slot + 1 ran without a plan of this loop (after a resume or a stall:
        startup.py): its pending plan, if any, is dropped; the tracks are predicted (unless the
        pending plan's prediction already did) and take the reports that arrived, with the shares
        they were measured with. Status `held`, or `unobserved` when nothing arrived; a UAV
        without a report has a null position in the line (compute_xy [M, 2], finite, is used
        for the computation only, where it contributes nothing)."""
        if n != self.slot + 1:
            raise ValueError(f"slot {n} is not the next slot {self.slot + 1}")
        s = self._scenario
        if self.pending is None:
            self.start_known_tracks()
            self.predict()  # unless a plan dropped after a stall did
        known = np.full((s.M, 2), np.nan)
        eta = np.array(self.eta, dtype=float)
        for m, msg in msgs.items():
            known[m] = msg.uav_xy_m
            eta[m] = msg.bandwidth_share
        status = HELD if msgs else UNOBSERVED
        reason = (
            f"{status}: no plan of the ground loop for this slot ({why}); "
            f"{len(msgs)} of {s.M} reports"
        )
        assoc = self.assoc if self.assoc is not None else np.full(s.M, NO_BS, dtype=np.int64)
        plan = SlotPlan(
            known, assoc, eta, float("nan"), SolveReport(status, reason, fallback=status)
        )
        self.pending = PendingPlan(n, plan, 0, np.asarray(compute_xy, dtype=float))
        slot = self.process(n, msgs, truth, compute_xy)
        self.last_plan = None  # this slot had no plan of ours: the next one starts afresh
        return replace(slot, uav_xy_m=known)


def live_trace_config(
    planning: Scenario, method: str, limits: Mapping[str, object]
) -> dict[str, object]:
    """The config line of a live multi-target trace: the planning scenario's config, its seed
    and the method, and `limits` over them (GroundSettings.trace_config: the vehicles' real
    limits beside the planner's, service/assembly.py `live_trace_limits`)."""
    return planning.trace_config() | {"seed": planning.seed, "method": method} | dict(limits)


def resume_refusal(path: Path, config: Mapping[str, object], n_slots: int) -> str | None:
    """Why the multi-target trace at `path` must not be continued by a mission that writes
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
    if not progress.multi_target:
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


def _origins(truth: TruthSetMsg | None, m: int, k: int) -> IntArray:
    """[k] the origins of UAV m's k measurements, as the world's truth gave them."""
    if truth is not None and m < len(truth.origins) and len(truth.origins[m]) == k:
        return np.asarray(truth.origins[m], dtype=np.int64)
    return np.full(k, NO_ORIGIN, dtype=np.int64)


def _with_status(plan: SlotPlan, status: str, reason: str, solve_s: float = 0.0) -> SlotPlan:
    """A hold plan with its status, why, and the time spent before it (s)."""
    fallback = "" if status == OPERATOR_HOLD else status
    report = SolveReport(status, reason, solve_s=solve_s, fallback=fallback)
    return replace(plan, report=report)


def track_set_message(slot: MultiTargetSlot, t_s: float) -> TrackSetMsg:
    """The `track_set` of a slot's tracks, stamped with the wall clock."""
    entries = tuple(
        TrackEntry(
            track_id=t.track_id,
            confirmed=t.confirmed,
            x=t.belief.x,
            P=t.belief.P,
            pcrb_position_trace=float(np.trace(t.bound.C[:2, :2])),
        )
        for t in slot.tracks
    )
    return TrackSetMsg(slot=slot.slot, t_s=t_s, tracks=entries, published_wall_s=time.time())


class MultiTargetGround(BusLoop):
    """Runs one multi-target mission over Zenoh: plan 1 at mission start, then slot by slot to
    slot N. on_slot(slot, latency_s) is called after each slot's plan is out."""

    state: MultiTargetMission

    def __init__(
        self,
        scenario: Scenario,
        bus: ZenohBus,
        settings: GroundSettings,
        kit: SolverKit | None = None,
        on_slot: Callable[[MultiTargetSlot, float], None] | None = None,
        initial_errors: FloatArray | None = None,
    ) -> None:
        super().__init__(scenario, bus, settings)
        self.state = MultiTargetMission(
            scenario, kit or multi_target_kit(scenario), settings.method, initial_errors
        )
        self.initial_errors = initial_errors
        self.on_slot = on_slot
        self.slots: deque[MultiTargetSlot] = deque(maxlen=SLOTS_KEPT)
        """The last SLOTS_KEPT slots (the trace keeps every one)."""
        self.detections = DetectionAssembler[DetectionSetMsg](
            scenario.M, scenario.N, settings, self.report.counters
        )
        self.truth: dict[int, TruthSetMsg] = {}
        self._trace: IO[str] | None = None
        self.last_traced = 0
        """The last slot in the trace (a resumed trace's last slot before this run's)."""

    # ------------------------------------------------------------------ lifecycle

    def trace_config(self) -> dict[str, object]:
        """The config line this loop writes (docs/trace.md)."""
        return live_trace_config(self.s, self.settings.method, self.settings.trace_config)

    def _open_trace(self) -> None:
        """Create the trace with its config line, or (settings.resume) continue it after its
        last complete slot: a torn last line is cut off, and the mission goes on from the last
        slot line (ConfigError when the trace is another mission's or config's, or its line
        cannot be continued). A trace killed before its config line was complete starts
        afresh."""
        path = self.settings.trace_path
        if path is None:
            return
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        if self.settings.resume and path.exists() and b"\n" in path.read_bytes():
            self._resume_trace(path)
            return
        if self.settings.resume and path.exists():
            log.warning("%s has no complete line; starting a new trace", path)
        self._trace = open(path, "w", encoding="utf-8")  # noqa: SIM115 (closed in run)
        self._write_line(header_line(self.trace_config()))

    def _resume_trace(self, path: Path) -> None:
        """Continue the trace at `path` (see _open_trace)."""
        refusal = resume_refusal(path, self.trace_config(), self.s.N)
        if refusal is not None:
            raise ConfigError(f"--resume: {refusal}")
        progress = trace_progress(path)
        if progress.last_line is not None:
            point = resume_point(progress.last_line)
            try:
                self.state = MultiTargetMission.resumed(
                    self.s, self.state.kit, self.settings.method, point, self.initial_errors
                )
            except ValueError as err:
                raise ConfigError(f"--resume: cannot continue {path}: {err}") from None
            self.last_traced = point.slot
            self.gate.close("resume")
            log.info("resuming after slot %d from %s", point.slot, path)
        data = path.read_bytes()
        with path.open("r+b") as raw:  # a torn last line (killed inside write) is cut off
            raw.truncate(data.rfind(b"\n") + 1)
            raw.flush()
            os.fsync(raw.fileno())
        self._trace = open(path, "a", encoding="utf-8")  # noqa: SIM115 (closed in run)

    def _close_trace(self) -> None:
        if self._trace is not None:
            self._write_line(end_line(self.mission_end(self.last_traced)))
            self._trace.close()

    def _write_line(self, line: str) -> None:
        f = self._trace
        if f is None:
            return
        f.write(line + "\n")
        f.flush()
        os.fsync(f.fileno())

    def _handlers(self) -> dict[str, Callable[[bytes], None]]:
        return {"truth": self._on_truth, "detections": self._on_detection}

    # ------------------------------------------------------------------ inputs

    def _on_detection(self, payload: bytes) -> None:
        self.detections.add(decode(DetectionSetMsg, payload, n_uavs=self.s.M), self.state.slot)

    def _on_truth(self, payload: bytes) -> None:
        msg = decode(TruthSetMsg, payload)
        if msg.slot > self.state.slot:
            self.truth[msg.slot] = msg

    # ------------------------------------------------------------------ the slot machine

    def _uav_positions(self, det_xy: FloatArray | None = None) -> FloatArray:
        """Where the UAVs are: fresh telemetry, else the slot's report positions, else the last
        plan's waypoints, else the start points."""
        xy = self.vehicles.positions(self.t_s, det_xy)
        last = self.state.last_plan
        fallback = self.s.uav_start_xy if last is None else last.uav_xy_m
        return np.where(np.isfinite(xy), xy, fallback)

    def _advance(self) -> None:
        st = self.state
        if self.done.is_set() or self.planning is not None:
            return
        if self.gate.closed and not self._open_gate():
            return
        if st.pending is None and not st.done and self.mission_t0_s is not None:
            st.start_known_tracks()
            self._start_planning(self._uav_positions(), None)
        while (
            self.planning is None
            and st.pending is not None
            and self.detections.ready(st.pending.slot, self.t_s, self.mission_t0_s, self.s.dt)
        ):
            self._process_slot(st.pending.slot)
        if st.done and self.planning is None:
            self.done.set()

    def _open_gate(self) -> bool:
        """Open the gate once the vehicles reported (startup.py); the slots the world has run
        meanwhile without a plan of this loop (after a resume or a stall) are traced `held`
        or `unobserved`."""
        t0 = self.mission_t0_s
        if t0 is None or not self.gate.try_open(self.vehicles, self.t_s):
            return False
        st = self.state
        world_slot = SlotTimeline(t0, self.s.dt).slot_of(self.t_s)
        for n in range(st.slot + 1, min(world_slot, self.s.N) + 1):
            msgs = self.detections.take(n)
            slot = st.skip(n, msgs, self._truth_of(n), self._uav_positions(), self.gate.reason)
            self._publish_tracks(slot)
            self._complete(slot, 0.0)
        return True

    def _publish_tracks(self, slot: MultiTargetSlot) -> None:
        self._publish(self.keys.track, lambda: encode(track_set_message(slot, self.t_s)))

    def _truth_of(self, n: int) -> TruthSetMsg | None:
        """The world's truth of slot n, if it came (older ones are dropped)."""
        truth = self.truth.pop(n, None)
        for old in [k for k in self.truth if k < n]:
            del self.truth[old]
        return truth

    def _process_slot(self, n: int) -> None:
        msgs = self.detections.take(n)
        det_xy = np.full((self.s.M, 2), np.nan)
        for m, msg in msgs.items():
            det_xy[m] = msg.uav_xy_m
        truth = self._truth_of(n)
        slot = self.state.process(n, msgs, truth, self._uav_positions(det_xy))
        self._publish_tracks(slot)
        latency_from = self.detections.last_detection_wall if msgs else None
        if latency_from is not None:
            self.report.last_detection_wall_s[n] = latency_from
            self.report.last_detection_wall_s.pop(n - SLOTS_KEPT, None)
        if self.state.done:
            self._complete(slot, 0.0)
            return
        self.state.start_known_tracks()
        self._start_planning(self._uav_positions(det_xy), latency_from, slot, det_xy)

    def _start_planning(
        self,
        uav_xy: FloatArray,
        latency_from: float | None,
        done: MultiTargetSlot | None = None,
        boundary_xy: FloatArray | None = None,
    ) -> None:
        st = self.state
        excluded = tuple(sorted(self.vehicles.excluded))
        held = self.vehicles.operator_held()
        v = self.vehicles.velocities(self.t_s)
        if st.last_plan is not None and not excluded:
            uav_xy, v = leg_start_state(uav_xy, v, st.last_plan, range(self.s.M), boundary_xy)
        predictions = st.predict()
        self.planning = asyncio.get_running_loop().create_task(
            self._plan(st.slot + 1, predictions, uav_xy, v, excluded, held, latency_from, done),
            name=f"plan-{st.slot + 1}",
        )

    async def _plan(
        self,
        n: int,
        predictions: tuple[TrackPrediction, ...],
        uav_xy: FloatArray,
        uav_v: FloatArray,
        excluded: tuple[int, ...],
        operator_held: tuple[int, ...],
        latency_from: float | None,
        done: MultiTargetSlot | None,
    ) -> None:
        st = self.state
        t0 = time.perf_counter()
        budget = self.settings.plan_budget_s
        future = in_daemon_thread(
            lambda: st.plan(predictions, uav_xy, uav_v, excluded, operator_held), f"plan-{n}"
        )
        try:
            async with asyncio.timeout(budget):
                planned_for, plan = await asyncio.shield(future)
        except TimeoutError:
            self.report.counters["plans timed out"] += 1
            why = f"timeout: planning took longer than the {budget:g} s budget; hold"
            planned_for = 0
            hold = hold_without_track(self.s, uav_xy, st.eta, st.assoc)
            plan = _with_status(hold, "timeout", why, time.perf_counter() - t0)
            future.add_done_callback(consume_result)
            st.renew_kits()
        except Exception as err:  # any planner failure: fall back, say why, go on
            self.report.counters["planner errors"] += 1
            why = f"solver error: {type(err).__name__}: {err}"
            planned_for, plan = self._fallback_after_error(
                why, time.perf_counter() - t0, predictions, uav_xy, uav_v, excluded, operator_held
            )
        self.planning = None
        try:
            if self.gate.tick() is not None or self.gate.closed:
                # Made before a stall: never published (startup.py); planned again from the
                # same prediction once the gate opens, or the slot is traced `held`.
                self.report.counters["plans dropped after a stall"] += 1
            else:
                plan = self._marked_if_late(n, plan)
                st.commit(n, planned_for, plan, uav_xy, excluded)
                msg = PlanMsg.from_plan(n, self.t_s, plan)
                self._publish(self.keys.plan, lambda: encode(msg))
                if plan.report.status == OPERATOR_HOLD:
                    log.info("slot %d: %s", n, plan.report.reason)
                elif plan.report.status != "ok":
                    self.report.last_error = f"slot {n}: {plan.report.reason}"
                    log.warning("slot %d: %s", n, plan.report.reason)
            latency = 0.0 if latency_from is None else time.monotonic() - latency_from
            if latency_from is not None:
                self.report.latencies_s.append(latency)
            if done is not None:
                self._complete(done, latency)
        except Exception as err:
            self._internal_error(err)
        self._advance_guarded()

    def _fallback_after_error(
        self,
        why: str,
        solve_s: float,
        predictions: tuple[TrackPrediction, ...],
        uav_xy: FloatArray,
        uav_v: FloatArray,
        excluded: tuple[int, ...],
        operator_held: tuple[int, ...],
    ) -> tuple[int, SlotPlan]:
        """After a planner error, as the single-target loop (planning/fleet.py
        `after_solver_error`): the communication-optimal plan (method "comm") for the active
        vehicles, the tracks and the excluded vehicles as keep-out points; if that fails too,
        every vehicle holds. Status "solver error" either way; (planned_for, plan)."""
        st = self.state
        planned_for = 0

        def comm() -> SlotPlan:
            nonlocal planned_for
            planned_for, plan = st.plan(
                predictions, uav_xy, uav_v, excluded, operator_held, method="comm"
            )
            return plan

        def hold(reason: str) -> SlotPlan:
            nonlocal planned_for
            planned_for = 0
            held = hold_without_track(self.s, uav_xy, st.eta, st.assoc)
            return _with_status(held, SOLVER_ERROR, reason, solve_s)

        plan = after_solver_error(why, solve_s, comm, hold)
        return planned_for, plan

    def _complete(self, slot: MultiTargetSlot, latency_s: float) -> None:
        """Slot n is done once plan n+1 is out: trace line, counters, health, on_slot."""
        self._write_line(slot_line(slot, {"latency_ms": latency_s * 1e3, **resume_fields(slot)}))
        self.last_traced = slot.slot
        self.slots.append(slot)
        self.report.counters["slots"] += 1
        if slot.plan.report.status != "ok":
            self.report.counters[f"slots {slot.plan.report.status}"] += 1
        self._publish_health("running")
        if self.on_slot is not None:
            self.on_slot(slot, latency_s)
