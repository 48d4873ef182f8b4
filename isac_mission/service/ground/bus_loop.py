"""What the ground loop (loop.py) does on the bus, apart from its slot machine.

One subscription to everything of the mission (so that each publisher's order is kept: the
world publishes a slot's truth before its detections), dispatched by the key's first part;
a wall ticker that lets wall-clock deadlines pass without traffic; `clock`, `telemetry` and
`control` handled alike; invalid payloads counted by reason and dropped; a bug in the slot
machine counted and logged while the loop goes on; `health` published on every change. The loop
adds its own handlers (`truth`, `detections`), its trace, and its slot machine (`_advance`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import replace
from typing import Protocol

from isac_mission.bus import Subscription, ZenohBus
from isac_mission.config import Scenario
from isac_mission.errors import MessageError
from isac_mission.records import MissionEnd
from isac_mission.service.ground.control import ControlDesk, ControlledMission
from isac_mission.service.ground.exclusion import VehicleWatch
from isac_mission.service.ground.report import GroundReport
from isac_mission.service.ground.settings import GroundSettings
from isac_mission.service.ground.startup import PlanningGate
from isac_mission.timebase import SlotTimeline, plan_is_late
from isac_mission.types import SlotPlan
from isac_mission.wire import (
    MAX_REASON_CHARS,
    ClockMsg,
    HealthMsg,
    Keys,
    TelemetryMsg,
    decode,
    encode,
    rejection_reason,
)

log = logging.getLogger(__name__)

WALL_TICK_S = 0.05
"""How often (wall s) the loop wakes without traffic."""


class LoopMission(ControlledMission, Protocol):
    """A loop's mission state: the last processed slot, the scenario, and whether slot N is
    done."""

    @property
    def done(self) -> bool: ...


class BusLoop:
    """The bus side of a ground loop (module doc); a subclass sets `state` before `run` and
    implements `_advance`, `_open_trace`, `_close_trace` and `_handlers`."""

    state: LoopMission

    def __init__(self, scenario: Scenario, bus: ZenohBus, settings: GroundSettings) -> None:
        self.bus = bus
        self.keys = Keys(scenario.mission_id)
        self.settings = settings
        self.report = GroundReport()
        self.t_s = 0.0
        self.mission_t0_s: float | None = None
        self.vehicles = VehicleWatch(scenario.M, settings, self.report)
        self.control = ControlDesk(
            self.keys, bus, self.vehicles, self.report, lambda: self.state, lambda: self.t_s
        )
        self.done = asyncio.Event()
        self.planning: asyncio.Task[None] | None = None
        self.gate = PlanningGate(scenario.M, settings)
        """Plans wait for fresh telemetry at the start, on a resume and after a stall."""

    @property
    def s(self) -> Scenario:
        """The scenario planned with (an operator's `set` changes it: control.py)."""
        return self.state.scenario

    def mission_end(self, last_traced: int) -> MissionEnd:
        """How this run stands as it ends (the trace's `end` line): complete once slot N is
        done, else interrupted (it was asked to stop first); last_traced: the last slot in the
        trace (a slot processed but whose record waited for the next plan is not in it)."""
        status = "complete" if self.state.done else "interrupted"
        return MissionEnd(status, last_traced, self.s.N)

    # ------------------------------------------------------------------ for the subclass

    def _handlers(self) -> dict[str, Callable[[bytes], None]]:
        """Key kind (`truth`, `detections`, ...) -> handler of a payload, beside the common
        `clock`, `telemetry` and `control`."""
        raise NotImplementedError

    def _open_trace(self) -> None:
        raise NotImplementedError

    def _close_trace(self) -> None:
        raise NotImplementedError

    def _advance(self) -> None:
        """Process every slot that is ready (the slot machine)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ lifecycle

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
            self._close_trace()
            self._publish_health("done" if self.state.done else "stopped")
        return self.report

    async def _pump(self, sub: Subscription) -> None:
        prefix = self.keys.prefix + "/"
        reply_key = self.keys.control_reply
        handlers: dict[str, Callable[[bytes], None]] = {
            "clock": self._on_clock,
            "telemetry": self._on_telemetry,
            "control": self._on_control,
            **self._handlers(),
        }
        async for key, payload in sub:
            if key == reply_key:  # our own replies (control/... is not a control request)
                continue
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
            await asyncio.sleep(WALL_TICK_S)
            self.gate.tick()
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
        self.report.count_internal_error(err)

    def _reject(self, err: MessageError) -> None:
        """An invalid payload: counted by reason, kept as the last error, logged (report.py)."""
        self.report.count_rejected(rejection_reason(err), err)

    # ------------------------------------------------------------------ common inputs

    def _on_clock(self, payload: bytes) -> None:
        msg = decode(ClockMsg, payload)
        self.t_s = max(self.t_s, msg.t_s)
        if msg.mission_t0_s is not None and self.mission_t0_s is None:
            self.mission_t0_s = msg.mission_t0_s

    def _on_telemetry(self, payload: bytes) -> None:
        self.vehicles.on_telemetry(decode(TelemetryMsg, payload, n_uavs=self.s.M))
        self._update_vehicle_states()

    def _on_control(self, payload: bytes) -> None:
        """An operator's request (control.py): executed or refused, always answered."""
        self.control.on_request(payload)
        self._update_vehicle_states()
        self._publish_health("running")

    def _update_vehicle_states(self) -> None:
        """Exclude or re-admit vehicles (exclusion.py); a change is announced in health."""
        if self.vehicles.update(self.t_s):
            self._publish_health("running")

    # ------------------------------------------------------------------ outputs

    def _marked_if_late(self, slot: int, plan: SlotPlan) -> SlotPlan:
        """`plan`, with fallback "late" when it is published so long after its slot's end that
        the bridges drop it (timebase.plan_is_late): the vehicles then fly on without it.
        Counted ("plans late")."""
        t0 = self.mission_t0_s
        if t0 is None:
            return plan
        end_s = SlotTimeline(t0, self.s.dt).slot_end_s(slot)
        if not plan_is_late(end_s, self.t_s, self.s.dt):
            return plan
        self.report.counters["plans late"] += 1
        why = f"late: published at {self.t_s:.1f} s, its slot ended at {end_s:.1f} s"
        reason = f"{why}; {plan.report.reason}" if plan.report.reason else why
        report = replace(plan.report, reason=reason, fallback=plan.report.fallback or "late")
        return replace(plan, report=report)

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
        rep, slot = self.report, max(self.state.slot, 0)
        msg = HealthMsg(
            slot=slot,
            t_s=self.t_s,
            status=status,
            counters=dict(rep.counters),
            last_error=rep.last_error,
            vehicles=self.vehicles.status(),
        )
        try:
            self.bus.publish(self.keys.health, encode(msg))
        except Exception as err:  # the bus may already be closing at shutdown
            log.debug("health not published: %s", err)
