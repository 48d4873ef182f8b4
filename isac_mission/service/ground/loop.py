"""The ground loop: detections -> EKF -> plan_slot -> plan, over Zenoh only.

It subscribes to `clock`, `detections/*`, `telemetry/*` and `truth` (truth goes into the trace for
evaluation; the planner never reads it) and publishes `plan`, `track` and `health`. Slot n is
processed once its detections are in or waited for (assembler.py): the EKF takes what arrived (a
partial update, counted). Invalid payloads are counted by reason, logged, and dropped; stale and
duplicate detections are dropped and counted, never used twice. The trace is written and flushed
slot by slot (tracefile.py).
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable

import numpy as np

from isac_mission.bus import ZenohBus
from isac_mission.config import Scenario
from isac_mission.planning.fallback import OPERATOR_HOLD
from isac_mission.planning.fleet import PlanningJob
from isac_mission.planning.slot import SolverKit
from isac_mission.records import SlotRecord, TraceWriter
from isac_mission.service.ground.assembler import DetectionAssembler
from isac_mission.service.ground.bus_loop import BusLoop
from isac_mission.service.ground.mission import MissionState
from isac_mission.service.ground.planner_thread import SOLVE_LOCK, consume_result, in_daemon_thread
from isac_mission.service.ground.report import SLOTS_KEPT, SlotEvent
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.startup import skip_slot
from isac_mission.service.ground.tracefile import open_trace
from isac_mission.types import FloatArray, Gaussian, SlotPlan
from isac_mission.wire import (
    DetectionMsg,
    PlanMsg,
    TrackMsg,
    TruthMsg,
    collect_detections,
    decode,
    encode,
)

log = logging.getLogger(__name__)


class GroundLoop(BusLoop):
    """Runs one mission over Zenoh: plan 1 at mission start, then slot by slot to slot N."""

    state: MissionState

    def __init__(
        self,
        scenario: Scenario,
        bus: ZenohBus,
        settings: GroundSettings,
        kit: SolverKit | None = None,
        on_slot: Callable[[SlotEvent], None] | None = None,
        initial_x: FloatArray | None = None,
    ) -> None:
        """initial_x [4]: the tracker's initial estimate (m, m/s), with covariance P0; None:
        the scenario's x0 (the cue)."""
        super().__init__(scenario, bus, settings)
        self.kit = kit if kit is not None else SolverKit(scenario, solve_lock=SOLVE_LOCK)
        self.on_slot = on_slot
        self.state = MissionState(
            scenario,
            self.kit,
            settings.method,
            Gaussian(
                np.array(scenario.x0 if initial_x is None else initial_x, dtype=float),
                scenario.P0.copy(),
            ),
        )
        self.writer: TraceWriter | None = None
        self.detections = DetectionAssembler[DetectionMsg](
            scenario.M, scenario.N, settings, self.report.counters
        )
        self.truth: dict[int, FloatArray] = {}

    # ------------------------------------------------------------------ lifecycle

    def _open_trace(self) -> None:
        opened = open_trace(self.s, self.settings)
        self.writer = opened.writer
        last = opened.last
        if last is not None:
            self.state = MissionState.resumed(self.s, self.kit, self.settings.method, last)
            self.gate.close("resume")
            log.info("resuming after slot %d from %s", self.state.slot, self.settings.trace_path)

    def _close_trace(self) -> None:
        if self.writer is not None:
            last = self.writer.last_record
            self.writer.write_end(self.mission_end(0 if last is None else last.slot))
            self.writer.close()

    def _handlers(self) -> dict[str, Callable[[bytes], None]]:
        return {"truth": self._on_truth, "detections": self._on_detection}

    # ------------------------------------------------------------------ inputs

    def _on_detection(self, payload: bytes) -> None:
        self.detections.add(decode(DetectionMsg, payload, n_uavs=self.s.M), self.state.slot)

    def _on_truth(self, payload: bytes) -> None:
        msg = decode(TruthMsg, payload)
        self.truth[msg.slot] = msg.target_x

    # ------------------------------------------------------------------ the slot machine

    def _uav_positions(self, det_xy: FloatArray | None = None) -> FloatArray:
        """Where the UAVs are: fresh telemetry, else the slot's detection positions, else the plan."""
        xy = self.vehicles.positions(self.t_s, det_xy)
        if np.any(~np.isfinite(xy)):
            last = self.state.pending.plan.uav_xy_m if self.state.pending else None
            if last is not None:
                fallback = last
            elif self.report.records:
                fallback = np.asarray(self.report.records[-1].uav_xy_m)
            else:
                fallback = self.s.uav_start_xy
            xy = np.where(np.isfinite(xy), xy, fallback)
        return xy

    def _advance(self) -> None:
        """Process every slot that is ready; plan slot 1 once the mission has started. Nothing
        moves while a plan is being made (slot n+1 needs plan n+1's prediction)."""
        if self.done.is_set() or self.planning is not None:
            return
        if self.gate.closed and not self._open_gate():
            return
        if self.state.pending is None and not self.state.done and self.mission_t0_s is not None:
            # Slot 1 at mission start, or the slot after the last traced one on a resume.
            self._start_planning(self._uav_positions(), latency_from=None, record=None)
        while (
            self.planning is None
            and self.state.pending is not None
            and self._slot_ready(self.state.pending.slot)
        ):
            self._process_slot(self.state.pending.slot)
        if self.state.done and self.planning is None:
            self.done.set()

    def _open_gate(self) -> bool:
        """Open the gate once the vehicles reported; trace the slots missed (startup.py)."""
        t0 = self.mission_t0_s
        if t0 is None or not self.gate.try_open(self.vehicles, self.t_s):
            return False
        for n in self.gate.slots_to_skip(self.state, self.t_s, t0):
            msgs = self.detections.take(n)
            record = skip_slot(self.state, n, msgs, self._uav_positions(), self.gate.reason)
            self._complete_record(*self._track_and_truth(n, record), 0.0)
        return True

    def _slot_ready(self, n: int) -> bool:
        return self.detections.ready(n, self.t_s, self.mission_t0_s, self.s.dt)

    def _process_slot(self, n: int) -> None:
        msgs = self.detections.take(n)
        det = collect_detections(n, msgs.values(), self.s.M)
        pending = self.state.pending
        assert pending is not None
        eta = pending.plan.bandwidth_share.copy()
        for m, msg in msgs.items():
            eta[m] = msg.bandwidth_share
        record = self.state.process(det, eta, self._uav_positions())
        record, truth = self._track_and_truth(n, record)
        latency_from = self.detections.last_detection_wall if msgs else None
        if latency_from is not None:
            self.report.last_detection_wall_s[n] = latency_from
            self.report.last_detection_wall_s.pop(n - SLOTS_KEPT, None)
        if self.state.done:
            self._complete_record(record, truth, 0.0)
        else:
            self._start_planning(
                self._uav_positions(det.uav_xy_m), latency_from, (record, truth), det.uav_xy_m
            )

    def _track_and_truth(self, n: int, record: SlotRecord) -> tuple[SlotRecord, FloatArray | None]:
        """Publish slot n's track; the record with the world's truth for slot n (if it came)."""
        b, j = self.state.belief, self.state.bound
        track = TrackMsg(
            slot=n,
            t_s=self.t_s,
            x=b.x,
            P=b.P,
            J=j.J,
            pcrb_trace=j.trace,
            published_wall_s=time.time(),
        )
        self._publish(self.keys.track, lambda: encode(track))
        truth = self.truth.pop(n, None)
        if truth is not None:
            record = SlotRecord.from_dict(record.to_dict() | {"target_true": truth.tolist()})
        return record, truth

    def _complete_record(
        self, record: SlotRecord, truth: FloatArray | None, latency: float
    ) -> None:
        """Slot n is done once plan n+1 is out: trace line, counters, health, on_slot."""
        extra: dict[str, object] = {"latency_ms": latency * 1e3}
        if self.vehicles.excluded:
            extra["excluded"] = sorted(self.vehicles.excluded)
        record = SlotRecord.from_dict(record.to_dict() | extra)
        if self.writer is not None:
            self.writer.write_slot(record)
        self.report.records.append(record)
        self.report.totals.add(record)
        self.report.counters["slots"] += 1
        if record.status != "ok":
            self.report.counters[f"slots {record.status}"] += 1
        self._publish_health("running")
        if self.on_slot is not None:
            err = (
                None if truth is None else float(np.linalg.norm(record.target_est[:2] - truth[:2]))
            )
            links = self.vehicles.links()
            self.on_slot(SlotEvent(record, err, latency, links))

    def _start_planning(
        self,
        uav_xy: FloatArray,
        latency_from: float | None,
        record: tuple[SlotRecord, FloatArray | None] | None,
        boundary_xy: FloatArray | None = None,
    ) -> None:
        """Plan the next slot on the planner thread, within the time budget; then publish it
        and complete `record` (the slot just processed, with its truth). boundary_xy [M, 2]:
        where the slot's detections say the vehicles were at its end (NaN = unknown)."""
        self._update_vehicle_states()
        job = self.state.next_job(
            uav_xy,
            self.vehicles.velocities(self.t_s),
            tuple(self.vehicles.excluded),
            boundary_xy,
            self.vehicles.operator_held(),
        )
        self.planning = asyncio.get_running_loop().create_task(
            self._plan(job, latency_from, record), name=f"plan-{job.slot}"
        )

    async def _plan(
        self,
        job: PlanningJob,
        latency_from: float | None,
        record: tuple[SlotRecord, FloatArray | None] | None,
    ) -> None:
        t0 = time.perf_counter()
        budget = self.settings.plan_budget_s
        future = in_daemon_thread(lambda: job.run(self.settings.planner), f"plan-{job.slot}")
        try:
            async with asyncio.timeout(budget):
                plan = await asyncio.shield(future)
        except TimeoutError:
            self.report.counters["plans timed out"] += 1
            why = f"timeout: planning took longer than the {budget:g} s budget; hold"
            plan = job.hold(why, "timeout", solve_s=time.perf_counter() - t0)
            future.add_done_callback(consume_result)
            # The late thread keeps its kit; the next slot plans on fresh ones.
            self.state.renew_kits()
        except Exception as err:  # any planner failure: fall back, say why, go on
            self.report.counters["planner errors"] += 1
            why = f"solver error: {type(err).__name__}: {err}"
            plan = job.fallback_after_error(why, time.perf_counter() - t0)
        self.planning = None
        try:
            self._finish_planning(job, plan, latency_from, record)
        except Exception as err:
            self._internal_error(err)
        self._advance_guarded()

    def _finish_planning(
        self,
        job: PlanningJob,
        plan: SlotPlan,
        latency_from: float | None,
        record: tuple[SlotRecord, FloatArray | None] | None,
    ) -> None:
        if self.gate.tick() is not None or self.gate.closed:
            # Made before a stall: never published (startup.py); replanned once it opens.
            self.report.counters["plans dropped after a stall"] += 1
        else:
            plan = self._marked_if_late(job.slot, plan)
            pending = self.state.commit(job, plan)
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
        if record is not None:
            self._complete_record(record[0], record[1], latency)
