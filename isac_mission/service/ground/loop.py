"""The ground loop: reports -> tracks -> plan, over Zenoh only, for any number of targets.

It subscribes to `clock`, `detections/*`, `telemetry/*`, `control` and `truth` (truth goes into
the trace for evaluation; the tracker and the planner never read it) and publishes `plan`,
`track` and `health`. Slot n is processed once its reports are in or waited for (assembler.py):
the tracker takes what arrived (a UAV whose report did not arrive contributes nothing). Then the
slot's tracks go out, and slot n + 1 is planned for the predicted tracks on the planner thread
within the time budget; the slot's trace line is written and flushed once that plan is out
(tracefile.py). Invalid payloads are counted by reason, logged, and dropped; stale and duplicate
reports are dropped and counted, never used twice.

What happens when things go wrong: plans wait for fresh telemetry at the start, on a resume and
after a stall (startup.py's gate), and the slots the world ran meanwhile are traced `held` or
`unobserved`; a plan over budget is a hold (status "timeout"); a solver error flies the
communication-optimal plan (a hold only if that fails too: planning/fleet.py); a plan the
bridges would drop is marked "late" (BusLoop._marked_if_late); a plan made before a stall is
dropped and made again; operators' requests are answered (control.py); a vehicle out of the plan
holds and the others plan around it (planning/fleet.py).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

import numpy as np

from isac_mission.bus import ZenohBus
from isac_mission.config import Scenario
from isac_mission.errors import ConfigError
from isac_mission.planning.fallback import OPERATOR_HOLD
from isac_mission.planning.fleet import PlanningJob
from isac_mission.planning.kit import SolverKit
from isac_mission.planning.tracks import TracksPlan
from isac_mission.records.tracks import TracksSlot
from isac_mission.service.ground.assembler import DetectionAssembler
from isac_mission.service.ground.bus_loop import BusLoop
from isac_mission.service.ground.mission import (
    ArrivedTruth,
    GroundSlot,
    MissionState,
)
from isac_mission.service.ground.planner_thread import SOLVE_LOCK, consume_result, in_daemon_thread
from isac_mission.service.ground.report import SLOTS_KEPT, SlotEvent
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.tracefile import slot_output
from isac_mission.tracking.factory import keep_out_tracks, restored_tracker
from isac_mission.types import FloatArray
from isac_mission.wire import DetectionMsg, DetectionSetMsg, PlanMsg, decode, encode

log = logging.getLogger(__name__)


class GroundLoop(BusLoop):
    """Runs one mission over Zenoh: plan 1 at mission start, then slot by slot to slot N.

    on_slot(event) is called after each slot of a labelled target once its plan is out;
    on_tracks(slot, latency_s) after each slot of a tracker of several targets (tracefile.py).
    initial_errors [T, 4]: added to each known target's configured state to start its track
    (the offline twin's x_hat - x; None: the configured state, the cue)."""

    state: MissionState

    def __init__(
        self,
        scenario: Scenario,
        bus: ZenohBus,
        settings: GroundSettings,
        kit: SolverKit | None = None,
        on_slot: Callable[[SlotEvent], None] | None = None,
        initial_errors: FloatArray | None = None,
        on_tracks: Callable[[TracksSlot, float], None] | None = None,
    ) -> None:
        super().__init__(scenario, bus, settings)
        self.kit = (
            kit
            if kit is not None
            else SolverKit(scenario, n_keep_out=keep_out_tracks(scenario), solve_lock=SOLVE_LOCK)
        )
        self.initial_errors = initial_errors
        self.state = MissionState(scenario, self.kit, settings.method, initial_errors)
        self.output = slot_output(
            scenario, self.state.tracker, settings, self.report, on_slot, on_tracks
        )
        self.detections = DetectionAssembler[DetectionMsg | DetectionSetMsg](
            scenario.M, scenario.N, settings, self.report.counters
        )
        self.truth: dict[int, ArrivedTruth] = {}

    # ------------------------------------------------------------------ lifecycle

    def _open_trace(self) -> None:
        resume = self.output.open()
        if resume is None:
            return
        s = self.s
        try:
            self.state = MissionState.resumed(
                s,
                self.kit,
                self.settings.method,
                restored_tracker(s, resume.saved),
                resume.slot,
                resume.eta,
                resume.assoc,
                self.initial_errors,
                resume.priorities,
            )
        except ValueError as err:
            path = self.settings.trace_path
            raise ConfigError(f"--resume: cannot continue {path}: {err}") from None
        self.gate.close("resume")
        log.info("resuming after slot %d from %s", resume.slot, self.settings.trace_path)

    def _close_trace(self) -> None:
        self.output.close(self.mission_end)

    def _handlers(self) -> dict[str, Callable[[bytes], None]]:
        return {"truth": self._on_truth, "detections": self._on_detection}

    # ------------------------------------------------------------------ inputs

    def _on_detection(self, payload: bytes) -> None:
        msg = decode(self.output.report_type, payload, n_uavs=self.s.M)
        self.detections.add(msg, self.state.slot)

    def _on_truth(self, payload: bytes) -> None:
        msg = decode(self.output.truth_type, payload)
        if msg.slot > self.state.slot:
            self.truth[msg.slot] = msg

    def _truth_of(self, n: int) -> ArrivedTruth | None:
        """The world's truth of slot n, if it came (older ones are dropped)."""
        truth = self.truth.pop(n, None)
        for old in [k for k in self.truth if k < n]:
            del self.truth[old]
        return truth

    # ------------------------------------------------------------------ the slot machine

    def _uav_positions(self, det_xy: FloatArray | None = None) -> FloatArray:
        """Where the UAVs are: fresh telemetry, else the slot's report positions, else the
        pending or last plan's waypoints, else the start points."""
        xy = self.vehicles.positions(self.t_s, det_xy)
        if np.any(~np.isfinite(xy)):
            st = self.state
            if st.pending is not None:
                fallback = st.pending.plan.uav_xy_m
            elif st.last_plan is not None:
                fallback = st.last_plan[2].uav_xy_m
            else:
                fallback = self.s.uav_start_xy
            xy = np.where(np.isfinite(xy), xy, np.where(np.isfinite(fallback), fallback, xy))
            xy = np.where(np.isfinite(xy), xy, self.s.uav_start_xy)
        return xy

    def _advance(self) -> None:
        """Process every slot that is ready; plan slot 1 once the mission has started. Nothing
        moves while a plan is being made (slot n+1 needs plan n+1's prediction)."""
        st = self.state
        if self.done.is_set() or self.planning is not None:
            return
        if self.gate.closed and not self._open_gate():
            return
        st = self.state
        if st.pending is None and not st.done and self.mission_t0_s is not None:
            # Slot 1 at mission start, or the slot after the last traced one on a resume.
            self._start_planning(self._uav_positions(), latency_from=None, done=None)
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
        for n in st.slots_to_skip(self.t_s, t0):
            msgs = self.detections.take(n)
            g = st.skip(n, msgs, self._truth_of(n), self._uav_positions(), self.gate.reason)
            self._publish_tracks(g)
            self._complete(g, 0.0)
        return True

    def _publish_tracks(self, g: GroundSlot) -> None:
        self._publish(self.keys.track, lambda: encode(self.output.track_message(g, self.t_s)))

    def _process_slot(self, n: int) -> None:
        msgs = self.detections.take(n)
        det_xy = np.full((self.s.M, 2), np.nan)
        for m, msg in msgs.items():
            det_xy[m] = msg.uav_xy_m
        g = self.state.process(n, msgs, self._truth_of(n), self._uav_positions(det_xy))
        self._publish_tracks(g)
        latency_from = self.detections.last_detection_wall if msgs else None
        if latency_from is not None:
            self.report.last_detection_wall_s[n] = latency_from
            self.report.last_detection_wall_s.pop(n - SLOTS_KEPT, None)
        if self.state.done:
            self._complete(g, 0.0)
            return
        self._start_planning(self._uav_positions(det_xy), latency_from, g, det_xy)

    def _complete(self, g: GroundSlot, latency_s: float) -> None:
        """Slot n is done once plan n+1 is out: trace line, counters, health, progress."""
        extra: dict[str, object] = {"latency_ms": latency_s * 1e3}
        if self.vehicles.excluded:
            extra["excluded"] = sorted(self.vehicles.excluded)
        self.output.complete(g, extra, latency_s, self.vehicles.links())
        self.report.counters["slots"] += 1
        if g.plan.report.status != "ok":
            self.report.counters[f"slots {g.plan.report.status}"] += 1
        self._publish_health("running")

    def _start_planning(
        self,
        uav_xy: FloatArray,
        latency_from: float | None,
        done: GroundSlot | None,
        boundary_xy: FloatArray | None = None,
    ) -> None:
        """Plan the next slot on the planner thread, within the time budget; then publish it
        and complete `done` (the slot just processed). boundary_xy [M, 2]: where the slot's
        reports say the vehicles were at its end (NaN = unknown)."""
        self._update_vehicle_states()
        job = self.state.next_job(
            uav_xy,
            self.vehicles.velocities(self.t_s),
            tuple(self.vehicles.excluded),
            boundary_xy,
            self.vehicles.operator_held(),
        )
        self.planning = asyncio.get_running_loop().create_task(
            self._plan(job, latency_from, done), name=f"plan-{job.slot}"
        )

    async def _plan(
        self, job: PlanningJob, latency_from: float | None, done: GroundSlot | None
    ) -> None:
        t0 = time.perf_counter()
        budget = self.settings.plan_budget_s
        future = in_daemon_thread(lambda: job.run_tracks(self.settings.planner), f"plan-{job.slot}")
        try:
            async with asyncio.timeout(budget):
                planned = await asyncio.shield(future)
        except TimeoutError:
            self.report.counters["plans timed out"] += 1
            why = f"timeout: planning took longer than the {budget:g} s budget; hold"
            planned = TracksPlan(0, None, job.hold(why, "timeout", time.perf_counter() - t0))
            future.add_done_callback(consume_result)
            # The late thread keeps its kit; the next slot plans on fresh ones.
            self.state.renew_kits()
        except Exception as err:  # any planner failure: fall back, say why, go on
            self.report.counters["planner errors"] += 1
            why = f"solver error: {type(err).__name__}: {err}"
            planned = job.fallback_after_error(why, time.perf_counter() - t0)
        self.planning = None
        try:
            self._finish_planning(job, planned, latency_from, done)
        except Exception as err:
            self._internal_error(err)
        self._advance_guarded()

    def _finish_planning(
        self,
        job: PlanningJob,
        planned: TracksPlan,
        latency_from: float | None,
        done: GroundSlot | None,
    ) -> None:
        if self.gate.tick() is not None or self.gate.closed:
            # Made before a stall: never published (startup.py); planned again from the same
            # prediction once the gate opens, or the slot is traced `held`.
            self.report.counters["plans dropped after a stall"] += 1
        else:
            plan = self._marked_if_late(job.slot, planned.plan)
            pending = self.state.commit(job, TracksPlan(planned.planned_for, None, plan))
            msg = PlanMsg.from_plan(pending.slot, self.t_s, pending.plan)
            self._publish(self.keys.plan, lambda: encode(msg))
            if plan.report.status == OPERATOR_HOLD:
                log.info("slot %d: %s", pending.slot, plan.report.reason)
            elif plan.report.status != "ok":
                self.report.last_error = f"slot {pending.slot}: {plan.report.reason}"
                log.warning("slot %d: %s", pending.slot, plan.report.reason)
        latency = 0.0
        if latency_from is not None:
            latency = time.monotonic() - latency_from
            self.report.latencies_s.append(latency)
        if done is not None:
            self._complete(done, latency)
