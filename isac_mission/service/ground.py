"""The ground loop: detections -> EKF -> plan_slot -> plan, over Zenoh only.

It subscribes to `clock`, `detections/*`, `telemetry/*` and `truth` (truth goes into the trace for
evaluation; the planner never reads it) and publishes `plan`, `track` and `health`. Slot n is
processed when all M detections of slot n have arrived (a missed detection arrives as null), or
when the simulation clock passes the slot boundary by `detection_wait_s`, or `detection_wall_wait_s`
of wall time after the first of them: then the EKF takes what arrived (a partial update, counted).
Invalid payloads are counted by reason, logged, and dropped; stale and duplicate detections are
dropped and counted, never used twice. The trace is written and flushed slot by slot.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import threading
import time
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np

from isac_mission.config import Scenario
from isac_mission.errors import MessageError
from isac_mission.planning.slot import Method, SolverKit, plan_slot
from isac_mission.records import SlotRecord, TraceWriter, read_trace
from isac_mission.service.bus import Keys, Subscription, ZenohBus
from isac_mission.service.codec import (
    MAX_REASON_CHARS,
    DetectionMsg,
    HealthMsg,
    PlanMsg,
    TelemetryMsg,
    TrackMsg,
    collect_detections,
    decode_clock,
    decode_control,
    decode_detection,
    decode_telemetry,
    decode_truth,
    encode_health,
    encode_plan,
    encode_track,
    rejection_reason,
)
from isac_mission.service.fleet_plan import Planner, PlanningJob
from isac_mission.service.mission import MissionState
from isac_mission.timebase import SlotTimeline, reached
from isac_mission.types import FloatArray, Gaussian, SlotPlan

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GroundSettings:
    """method: planning strategy; trace_path: JSON Lines trace (None: no trace); resume: continue
    an existing trace from its last complete slot; detection_wait_s: simulation seconds after a
    slot boundary before a partial update; detection_wall_wait_s: the same bound in wall seconds,
    counted from the first detection of the slot or from the clock reaching the slot's end,
    whichever comes first (for a held or stalled clock);
    telemetry_max_age_s: older telemetry is not used as a UAV position; trace_config: entries
    that override or extend the trace's config line.

    Faults (docs/reliability.md): plan_budget_s: wall seconds a slot's planning may take (None:
    no limit); past it the slot's plan is "hold" (status "timeout") and the next slot plans
    normally. vehicle_lost_after_s (simulation) and vehicle_lost_wall_s (wall): a vehicle whose
    telemetry position is older than both, or whose bridge reports its link lost, is planned
    around (fleet_plan.py) until its link is back and it is in OFFBOARD again.
    plan_rate_factor: the planner's R_th margin, applied to an operator's new R_th too.
    planner: the per-slot planning function (plan_slot; replaceable to inject faults)."""

    method: Method = "proposed"
    trace_path: Path | None = None
    resume: bool = False
    detection_wait_s: float = 0.5
    detection_wall_wait_s: float = 2.0
    telemetry_max_age_s: float = 1.0
    trace_config: dict[str, object] = field(default_factory=dict)
    plan_budget_s: float | None = 1.0
    vehicle_lost_after_s: float = 1.5
    vehicle_lost_wall_s: float = 1.0
    plan_rate_factor: float = 1.0
    planner: Planner = plan_slot


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


class GroundLoop:
    """Runs one mission over Zenoh: plan 1 at mission start, then slot by slot to slot N."""

    def __init__(
        self,
        scenario: Scenario,
        bus: ZenohBus,
        settings: GroundSettings,
        kit: SolverKit | None = None,
        on_slot: Callable[[SlotEvent], None] | None = None,
    ) -> None:
        self.s = scenario
        self.bus = bus
        self.keys = Keys(scenario.mission_id)
        self.settings = settings
        self.kit = kit if kit is not None else SolverKit(scenario)
        self.on_slot = on_slot
        self.report = GroundReport()
        self.state = MissionState(
            scenario, self.kit, settings.method, Gaussian(scenario.x0.copy(), scenario.P0.copy())
        )
        self.writer: TraceWriter | None = None
        self.t_s = 0.0
        self.mission_t0_s: float | None = None
        self.buffer: dict[int, dict[int, DetectionMsg]] = {}
        self.first_seen_wall: dict[int, float] = {}
        self.last_detection_wall = 0.0
        self.telemetry: dict[int, TelemetryMsg] = {}
        self.truth: dict[int, FloatArray] = {}
        self.done = asyncio.Event()
        self.excluded: dict[int, str] = {}
        """Vehicles planned around, with the reason."""
        self.telemetry_fresh_wall: dict[int, float] = {}
        """Vehicle -> wall time (time.monotonic) its telemetry position last advanced."""
        self.planning: asyncio.Task[None] | None = None
        self.resumed_xy: FloatArray | None = None
        """UAV positions of the last traced slot, after a resume (until telemetry is fresh)."""

    # ------------------------------------------------------------------ lifecycle

    def _open_trace(self) -> None:
        path = self.settings.trace_path
        if path is None:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        if self.settings.resume and path.exists() and b"\n" not in path.read_bytes():
            # Killed before its config line was complete: no slot to lose, start afresh.
            log.warning("%s has no complete line; starting a new trace", path)
        elif self.settings.resume and path.exists():
            trace = read_trace(path)
            self.writer = TraceWriter.resume(path, fsync=True)
            if trace.slots:
                last = trace.slots[-1]
                self.state = MissionState.resumed(self.s, self.kit, self.settings.method, last)
                self.resumed_xy = np.asarray(last.uav_xy, dtype=float)
                log.info("resuming after slot %d from %s", self.state.slot, path)
            return
        config = (
            self.s.trace_config()
            | {"seed": self.s.seed, "method": self.settings.method}
            | self.settings.trace_config
        )
        self.writer = TraceWriter(path, config, fsync=True)

    async def run(self, stop: asyncio.Event) -> GroundReport:
        """Run until slot N is done or `stop` is set; the trace is closed on the way out."""
        self._open_trace()
        # One subscription for everything, so that each publisher's order is kept (the world
        # publishes a slot's truth before its detections).
        sub = self.bus.subscribe(self.keys.everything)
        try:
            async with asyncio.TaskGroup() as tg:
                pump = tg.create_task(self._pump(sub))
                ticker = tg.create_task(self._wall_ticker())
                waiters = [
                    asyncio.ensure_future(stop.wait()),
                    asyncio.ensure_future(self.done.wait()),
                ]
                await asyncio.wait(waiters, return_when=asyncio.FIRST_COMPLETED)
                for task in (*waiters, pump, ticker):
                    task.cancel()
                if self.planning is not None:
                    self.planning.cancel()
        finally:
            sub.close()
            if self.writer is not None:
                self.writer.close()
            self._publish_health("done" if self.state.done else "stopped")
        return self.report

    async def _pump(self, sub: Subscription) -> None:
        prefix = self.keys.prefix + "/"
        handlers: dict[str, Callable[[bytes], None]] = {
            "clock": self._on_clock,
            "truth": self._on_truth,
            "detections": self._on_detection,
            "telemetry": self._on_telemetry,
            "control": self._on_control,
        }
        async for key, payload in sub:
            kind = key.removeprefix(prefix).split("/", 1)[0]
            handler = handlers.get(kind)
            if handler is None:  # plan, track, health: ours or another ground's
                continue
            try:
                handler(payload)
            except MessageError as err:
                self._reject(err)
            self._advance_guarded()

    async def _wall_ticker(self) -> None:
        """Wakes the loop so that a wall-clock deadline can pass without traffic."""
        while True:
            await asyncio.sleep(0.05)
            self._update_vehicle_states()
            self._advance_guarded()

    def _advance_guarded(self) -> None:
        """_advance, with a bug in it counted and logged instead of ending the service."""
        try:
            self._advance()
        except Exception as err:
            self._internal_error(err)

    def _internal_error(self, err: Exception) -> None:
        """A bug: counted, logged with its traceback, and the loop goes on."""
        self.report.counters["internal errors"] += 1
        self.report.last_error = f"internal error: {type(err).__name__}: {err}"[:MAX_REASON_CHARS]
        log.exception("ground loop: internal error (the loop goes on)")

    def _reject(self, err: MessageError) -> None:
        """Count an invalid payload under "rejected <reason>" (codec.rejection_reason), keep its
        message as the last error, and log it (the first few of each reason, then every 100th:
        a flood of garbage must not turn into a flood of log lines)."""
        name = f"rejected {rejection_reason(err)}"
        self.report.counters[name] += 1
        self.report.last_error = str(err)[:MAX_REASON_CHARS]
        n = self.report.counters[name]
        if n <= 5 or n % 100 == 0:
            log.warning("dropped message (%s #%d): %s", name, n, self.report.last_error)

    # ------------------------------------------------------------------ inputs

    def _on_clock(self, payload: bytes) -> None:
        msg = decode_clock(payload)
        self.t_s = max(self.t_s, msg.t_s)
        if msg.mission_t0_s is not None and self.mission_t0_s is None:
            self.mission_t0_s = msg.mission_t0_s

    def _on_detection(self, payload: bytes) -> None:
        msg = decode_detection(payload, n_uavs=self.s.M)
        if msg.slot == 0:
            self.report.counters["detections of slot 0 (before plan 1)"] += 1
            return
        if msg.slot <= self.state.slot:
            self.report.counters["detections stale"] += 1
            return
        if msg.slot > self.s.N:
            self.report.counters["detections beyond mission"] += 1
            return
        slot_buf = self.buffer.setdefault(msg.slot, {})
        if msg.uav in slot_buf:
            self.report.counters["detections duplicate"] += 1
            return
        slot_buf[msg.uav] = msg
        now = time.monotonic()
        self.first_seen_wall.setdefault(msg.slot, now)
        self.last_detection_wall = now

    def _on_telemetry(self, payload: bytes) -> None:
        msg = decode_telemetry(payload, n_uavs=self.s.M)
        last = self.telemetry.get(msg.uav)
        if last is None or msg.t_s > last.t_s:
            self.telemetry_fresh_wall[msg.uav] = time.monotonic()
        self.telemetry[msg.uav] = msg
        self._update_vehicle_states()

    def _on_control(self, payload: bytes) -> None:
        msg = decode_control(payload)
        r_th_mbps = msg.params["rate_min_mbps"]
        new = self.state.scenario.with_changes(
            r_th=r_th_mbps * 1e6 * self.settings.plan_rate_factor
        )
        self.state.set_scenario(new)
        self.s = new
        self.report.counters["operator commands"] += 1
        log.warning("operator: R_th = %.3f Mbit/s from slot %d on", r_th_mbps, self.state.slot + 2)
        self._publish_health("running")

    def _update_vehicle_states(self) -> None:
        """Exclude a vehicle whose link is lost or whose telemetry is stale; re-admit it once
        its link is back, its telemetry fresh and it is in OFFBOARD again."""
        now = time.monotonic()
        changed = False
        for m, tel in self.telemetry.items():
            age_s = self.t_s - tel.t_s
            stale = (
                age_s > self.settings.vehicle_lost_after_s
                and now - self.telemetry_fresh_wall.get(m, now) > self.settings.vehicle_lost_wall_s
            )
            if m not in self.excluded and (tel.link == "lost" or stale):
                why = "link lost" if tel.link == "lost" else f"telemetry {age_s:.1f} s old"
                self.excluded[m] = why
                self.report.counters["vehicle exclusions"] += 1
                self.report.last_error = f"vehicle {m}: {why}; planning around it"
                log.warning("vehicle %d: %s; planning the others around it", m, why)
                changed = True
            elif m in self.excluded and tel.link == "ok" and not stale and tel.mode == "offboard":
                del self.excluded[m]
                self.report.counters["vehicle readmissions"] += 1
                log.warning("vehicle %d: link back and in OFFBOARD; planning it again", m)
                changed = True
        if changed:
            self._publish_health("running")

    def _on_truth(self, payload: bytes) -> None:
        msg = decode_truth(payload)
        self.truth[msg.slot] = msg.target_x

    # ------------------------------------------------------------------ the slot machine

    def _uav_positions(self, det_xy: FloatArray | None = None) -> FloatArray:
        """Where the UAVs are: fresh telemetry, else the slot's detection positions, else the plan."""
        xy = np.array(det_xy, dtype=float) if det_xy is not None else np.full((self.s.M, 2), np.nan)
        for m in range(self.s.M):
            tel = self.telemetry.get(m)
            fresh = tel is not None and self.t_s - tel.t_s <= self.settings.telemetry_max_age_s
            if tel is not None and ((fresh and tel.link == "ok") or m in self.excluded):
                xy[m] = tel.position_xy_m  # an excluded vehicle holds where it was last seen
        if np.any(~np.isfinite(xy)):
            last = self.state.pending.plan.uav_xy_m if self.state.pending else None
            if last is not None:
                fallback = last
            elif self.report.records:
                fallback = np.asarray(self.report.records[-1].uav_xy)
            elif self.resumed_xy is not None:
                fallback = self.resumed_xy
            else:
                fallback = self.s.uav_start_xy
            xy = np.where(np.isfinite(xy), xy, fallback)
        return xy

    def _advance(self) -> None:
        """Process every slot that is ready; plan slot 1 once the mission has started. Nothing
        moves while a plan is being made (slot n+1 needs plan n+1's prediction)."""
        if self.done.is_set() or self.planning is not None:
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

    def _slot_ready(self, n: int) -> bool:
        got = self.buffer.get(n, {})
        if len(got) == self.s.M:
            return True
        now = time.monotonic()
        if self.mission_t0_s is not None:
            boundary = SlotTimeline(self.mission_t0_s, self.s.dt).slot_end_s(n)
            if reached(self.t_s, boundary + self.settings.detection_wait_s):
                return True
            if reached(self.t_s, boundary):
                # The wall wait also runs from the clock reaching the slot's end, so that a slot
                # whose detections were all lost does not wait for a held (lockstep) clock.
                self.first_seen_wall.setdefault(n, now)
        first = self.first_seen_wall.get(n)
        return first is not None and now - first > self.settings.detection_wall_wait_s

    def _process_slot(self, n: int) -> None:
        msgs = self.buffer.pop(n, {})
        self.first_seen_wall.pop(n, None)
        if len(msgs) < self.s.M:
            self.report.counters["slots with missing detections"] += 1
            self.report.counters["detections missing"] += self.s.M - len(msgs)
        det = collect_detections(n, msgs.values(), self.s.M)
        pending = self.state.pending
        assert pending is not None
        eta = pending.plan.bandwidth_share.copy()
        for m, msg in msgs.items():
            eta[m] = msg.bandwidth_share
        record = self.state.process(det, eta, self._uav_positions())
        truth = self.truth.pop(n, None)
        if truth is not None:
            record = SlotRecord.from_dict(record.to_dict() | {"target_true": truth.tolist()})
        latency_from = self.last_detection_wall if msgs else None
        if latency_from is not None:
            self.report.last_detection_wall_s[n] = latency_from
            self.report.last_detection_wall_s.pop(n - SLOTS_KEPT, None)
        self._publish(
            self.keys.track,
            lambda: encode_track(
                TrackMsg(
                    n,
                    self.t_s,
                    self.state.belief.x,
                    self.state.belief.P,
                    self.state.bound.J,
                    self.state.bound.trace,
                )
            ),
        )
        if self.state.done:
            self._complete_record(record, truth, 0.0)
        else:
            self._start_planning(self._uav_positions(det.uav_xy_m), latency_from, (record, truth))

    def _complete_record(
        self, record: SlotRecord, truth: FloatArray | None, latency: float
    ) -> None:
        """Slot n is done once plan n+1 is out: trace line, counters, health, on_slot."""
        extra: dict[str, object] = {"latency_ms": latency * 1e3}
        if self.excluded:
            extra["excluded"] = sorted(self.excluded)
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
            links = {m: t.link for m, t in self.telemetry.items()}
            self.on_slot(SlotEvent(record, err, latency, links))

    def _uav_velocities(self) -> FloatArray:
        """[M, 2] velocities from fresh telemetry (zero where there is none)."""
        v = np.zeros((self.s.M, 2))
        for m, tel in self.telemetry.items():
            if tel.link == "ok" and self.t_s - tel.t_s <= self.settings.telemetry_max_age_s:
                v[m] = tel.velocity_xy_mps
        return v

    def _start_planning(
        self,
        uav_xy: FloatArray,
        latency_from: float | None,
        record: tuple[SlotRecord, FloatArray | None] | None,
    ) -> None:
        """Plan the next slot on the planner thread, within the time budget; then publish it
        and complete `record` (the slot just processed, with its truth)."""
        self._update_vehicle_states()
        job = self.state.next_job(uav_xy, self._uav_velocities(), tuple(self.excluded))
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
        future = _in_daemon_thread(lambda: job.run(self.settings.planner), f"plan-{job.slot}")
        try:
            plan = await asyncio.wait_for(asyncio.shield(future), budget)
        except TimeoutError:
            self.report.counters["plans timed out"] += 1
            why = f"timeout: planning took longer than the {budget:g} s budget; hold"
            plan = job.hold(why, "timeout", solve_s=time.perf_counter() - t0)
            future.add_done_callback(_consume_result)
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
        pending = self.state.commit(job, plan)
        self._publish(
            self.keys.plan, lambda: encode_plan(PlanMsg(pending.slot, self.t_s, pending.plan))
        )
        if plan.report.status != "ok":
            self.report.last_error = f"slot {pending.slot}: {plan.report.reason}"
            log.warning("slot %d: %s", pending.slot, plan.report.reason)
        latency = 0.0
        if latency_from is not None:
            latency = time.monotonic() - latency_from
            self.report.latencies_s.append(latency)
        if record is not None:
            self._complete_record(record[0], record[1], latency)

    def _publish(self, key: str, encode: Callable[[], bytes]) -> None:
        """Publish encode() on `key`; a message that fails its own validation is counted and
        logged, and the slot goes on (the trace keeps everything)."""
        try:
            payload = encode()
        except MessageError as err:
            kind = key.rsplit("/", 1)[-1]
            self.report.counters[f"{kind} not published"] += 1
            self.report.last_error = f"{kind} not published: {err}"[:MAX_REASON_CHARS]
            log.error("%s not published: %s", kind, err)
            return
        self.bus.publish(key, payload)

    def _publish_health(self, status: str) -> None:
        try:
            self.bus.publish(
                self.keys.health,
                encode_health(
                    HealthMsg(
                        max(self.state.slot, 0),
                        self.t_s,
                        status,
                        dict(self.report.counters),
                        self.report.last_error,
                        {
                            m: f"excluded: {self.excluded[m]}" if m in self.excluded else "active"
                            for m in range(self.s.M)
                        },
                    )
                ),
            )
        except Exception as err:  # the bus may already be closing at shutdown
            log.debug("health not published: %s", err)


def _in_daemon_thread(fn: Callable[[], SlotPlan], name: str) -> asyncio.Future[SlotPlan]:
    """Run fn on a new daemon thread; its result as a future of the running loop. A daemon
    thread, so that a planner that never returns cannot keep the process from exiting."""
    loop = asyncio.get_running_loop()
    future: asyncio.Future[SlotPlan] = loop.create_future()

    def settle(result: SlotPlan | None, error: BaseException | None) -> None:
        if future.done():
            return
        if error is not None:
            future.set_exception(error)
        else:
            future.set_result(cast(SlotPlan, result))

    def target() -> None:
        try:
            result = fn()
        except BaseException as err:  # delivered to the loop, which decides
            with contextlib.suppress(RuntimeError):  # the loop may be closed by now
                loop.call_soon_threadsafe(settle, None, err)
            return
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(settle, result, None)

    threading.Thread(target=target, name=name, daemon=True).start()
    return future


def _consume_result(future: asyncio.Future[SlotPlan]) -> None:
    """Retrieve a timed-out plan's late result or error, so that asyncio does not log it."""
    if not future.cancelled():
        future.exception()
