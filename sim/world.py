"""The simulated world in one process: clock, vehicles, target, sensing, and its bus outputs.

`run_world(scenario, options, stop)` runs until `stop` is set:

- a `SimClock` (ticks of 1 / tick_hz simulation seconds at `speed` x real time) steps the M
  autopilots (`sim.autopilot.Autopilot`, one per UAV: spawned on the ground at the scenario's
  start points, MAVLink on 127.0.0.1 in PX4 SITL's layout: offboard link from
  mavlink_local_base_port + m to mavlink_base_port + m, GCS link from gcs_local_base_port + m
  to gcs_port) and drives everything else;
- at each slot boundary t = t0 + n dt it asks its scene (`sim.scenes.WorldScene`, picked from the
  scenario by `sim.world_assembly.make_scene`) for slot n: the truth, then every UAV's report
  drawn from the vehicles' actual horizontal positions with the shares of the plan in use; it
  publishes the truth (`truth` of the paper's labelled target, `truth_set` of several), the
  reports (`detection`, `detection_set`; `sim.emulator.SensingEmulator`) and `clock`; a slot the
  scene does not cover (past slot N with several targets) has the clock only;
- `clock` is also published every 1 / clock_rate_hz simulation seconds (slot -1 before the
  mission starts).

Mission start (t0): "immediate" (default) starts slot 0 at t = 0 with the vehicles on the ground
at their start points; "offboard" starts it at the first tick at which every vehicle is armed, in
OFFBOARD and within `start_altitude_tol_m` of the flight altitude H (docs/frames-and-clocks.md: the
vehicles take off, reach their start points and enter offboard; the ground loop or any MAVLink
client flies them there).

Slot convention: plan n carries the waypoints the vehicles fly to during (n-1, n] and the shares
eta_n of slot n's detections; the ground publishes plan n+1 after processing slot n. Lockstep
(`sim.lockstep`): after publishing slot n (for n < N) the clock holds at t0 + n dt until plan
n+1 (or a later one) has arrived, or `lockstep_timeout_s` wall seconds have passed, repeating
the clock message meanwhile.

The parts: options and counters `sim.world_options`, scene and vehicles `sim.world_assembly`,
what a slot shows `sim.scenes`, truth and clock publishing `sim.world_outputs`, reports and plans
`sim.emulator`.

Vehicle telemetry is not published on Zenoh here: it goes over MAVLink (the service's bridge
publishes it). The vehicles' local NED frames are all centred on the scenario origin (0, 0)
(north = y, east = x).
"""

from __future__ import annotations

import asyncio
import logging

from isac_mission.bus import ZenohBus
from isac_mission.config import Scenario
from isac_mission.timebase import SlotTimeline, reached
from isac_mission.wire import Keys
from sim.autopilot.endpoint import Autopilot
from sim.clock import SimClock
from sim.emulator import SensingEmulator
from sim.impaired_io import ImpairedPublisher
from sim.lockstep import Lockstep
from sim.scenes import WorldScene
from sim.world_assembly import (
    make_scene,
    make_vehicles,
    positions_xy_m,
    ready_for_offboard_start,
)
from sim.world_impairment import detection_publisher, impair_vehicles
from sim.world_options import WorldOptions, WorldStats
from sim.world_outputs import WorldOutputs

log = logging.getLogger(__name__)


class World:
    """Everything of `run_world`, for callers that want to look inside (tests, the lead's run).

    Use: `world = World(scenario, options); await world.open(); await world.run(stop);
    await world.close()` (close also after a failed open).
    """

    def __init__(self, scenario: Scenario, options: WorldOptions) -> None:
        self.scenario = scenario
        self.options = options
        self.keys = Keys(scenario.mission_id)
        self.stats = WorldStats()
        self.scene: WorldScene = make_scene(scenario, options)
        """The targets and their sensing, of the scenario's detection model."""
        self.clock = SimClock(tick_hz=options.tick_hz, speed=options.speed)
        self.vehicles = make_vehicles(scenario, options)
        self.bus: ZenohBus | None = None
        self.emulator: SensingEmulator | None = None
        self.outputs: WorldOutputs | None = None
        self.mission_t0_s: float | None = 0.0 if options.start == "immediate" else None
        self._outages_scheduled = False
        for outage in options.link_outages:
            if not 0 <= outage.vehicle < scenario.M:
                raise ValueError(f"link outage: no vehicle {outage.vehicle} (M = {scenario.M})")
        self._next_slot = 0
        self.lockstep = Lockstep(
            self.clock, options.lockstep_timeout_s, self.stats, self._republish_clock
        )
        self._opened_vehicles: list[Autopilot] = []
        self.impairment = options.impairment or scenario.impairment
        """Lossy, late links (the options', else the scenario's; sim.world_impairment)."""
        self.impairment_seed = next(
            s for s in (self.impairment.seed, options.seed, scenario.seed) if s is not None
        )
        self.detection_links: ImpairedPublisher | None = None

    # -- lifecycle ---------------------------------------------------------------------------

    async def open(self) -> None:
        """Open the Zenoh session and the vehicles' MAVLink sockets."""
        self.bus = await ZenohBus.open_async(self.options.bus)
        self.outputs = WorldOutputs(
            self.bus,
            self.keys,
            slot_s=self.scenario.dt,
            speed=self.options.speed,
            clock_rate_hz=self.options.clock_rate_hz,
        )
        self.detection_links = detection_publisher(
            self.bus,
            self.keys,
            self.scenario.M,
            self.impairment,
            self.impairment_seed,
            self.options.speed,
        )
        self.emulator = SensingEmulator(
            self.detection_links or self.bus, self.keys, self.scenario.M, n_bs=self.scenario.K
        )
        self.emulator.add_plan_listener(self._on_plan)
        for v in self.vehicles:
            await v.open()
            self._opened_vehicles.append(v)
        impair_vehicles(self.vehicles, self.impairment, self.impairment_seed, self.options.speed)

    async def run(self, stop: asyncio.Event) -> None:
        """Run until `stop` is set. Needs `open()` first."""
        bus, emulator = self.bus, self.emulator
        if bus is None or emulator is None:
            raise RuntimeError("World.run before World.open")
        plans = bus.subscribe(self.keys.plan)
        self.clock.add_tick_callback(self._on_tick)
        self._run_due_slots(self.clock.now_s)  # slot 0 at t = 0 for an immediate start
        if self.mission_t0_s is None:
            self._publish_clock(self.clock.now_s)
        try:
            async with asyncio.TaskGroup() as tg:
                tg.create_task(emulator.listen_plans(plans), name="world-plans")
                tg.create_task(self.clock.run(stop), name="world-clock")
                await stop.wait()
                plans.close()  # ends listen_plans; clock.run returns on stop
        finally:
            plans.close()
            self.clock.remove_tick_callback(self._on_tick)
            self.lockstep.cancel_timers()
            self._sync_stats()

    async def close(self) -> None:
        """Close the vehicles' sockets and the Zenoh session (idempotent)."""
        self.lockstep.cancel_timers()
        while self._opened_vehicles:
            v = self._opened_vehicles.pop()
            try:
                await v.close()
            except Exception as err:  # keep closing the rest
                log.warning("vehicle %d close: %s", v.system_id, err)
        if self.detection_links is not None:
            self.detection_links.close()
        if self.bus is not None:
            self.bus.close()

    # -- per tick ----------------------------------------------------------------------------

    def _on_tick(self, now_s: float, dt_s: float) -> None:
        for v in self.vehicles:
            v.step(now_s, dt_s)
        if self.mission_t0_s is None and ready_for_offboard_start(
            self.vehicles, self.scenario.H, self.options.start_altitude_tol_m
        ):
            self.mission_t0_s = now_s
            log.info("mission start at t = %.2f s: all vehicles in offboard at altitude", now_s)
        if self.mission_t0_s is not None and not self._outages_scheduled:
            self._outages_scheduled = True
            for outage in self.options.link_outages:
                self.vehicles[outage.vehicle].silence_radio(
                    self.mission_t0_s + outage.start_s, outage.duration_s
                )
        self._run_due_slots(now_s)
        outputs = self.outputs
        if outputs is not None and outputs.clock_due(now_s):
            self._publish_clock(now_s)

    def _timeline(self) -> SlotTimeline:
        assert self.mission_t0_s is not None
        return SlotTimeline(self.mission_t0_s, self.scenario.dt)

    def _slot_time(self, n: int) -> float:
        return self._timeline().slot_end_s(n)

    def _run_due_slots(self, now_s: float) -> None:
        if self.mission_t0_s is None:
            return
        while not self.lockstep.holding and reached(now_s, self._slot_time(self._next_slot)):
            n = self._next_slot
            self._next_slot = n + 1
            self._run_slot(n, now_s)

    def _run_slot(self, n: int, now_s: float) -> None:
        """Slot n: the scene's truth (first, so that an evaluator has it when the slot's reports
        complete) and every UAV's report, if the scene covers it; then the clock."""
        outputs, emulator = self.outputs, self.emulator
        assert outputs is not None and emulator is not None
        if self.scene.covers(n):
            t_s = self._slot_time(n)
            xy = positions_xy_m(self.vehicles)
            shown = self.scene.show(n, t_s, xy, emulator.shares_for(n))
            outputs.publish_truth(shown.truth)
            self.stats.truth_published += 1
            emulator.publish_reports(n, shown.reports)
            log.debug("slot %d at t = %.2f s: %d reports", n, t_s, len(shown.reports))
        self.stats.slots = n + 1
        self._publish_clock(now_s)
        if self.options.lockstep and n < self.scenario.N and emulator.latest_plan_slot < n + 1:
            self.lockstep.hold(n, now_s)

    def _on_plan(self, plan: object) -> None:
        emulator = self.emulator
        assert emulator is not None
        self.lockstep.plan_arrived(emulator.latest_plan_slot)

    # -- outputs -----------------------------------------------------------------------------

    def _current_slot(self, now_s: float) -> int:
        if self.mission_t0_s is None or not reached(now_s, self.mission_t0_s):
            return -1
        return min(self._next_slot - 1, max(0, self._timeline().slot_of(now_s)))

    def _publish_clock(self, now_s: float) -> None:
        outputs = self.outputs
        assert outputs is not None
        outputs.publish_clock(self._current_slot(now_s), now_s, self.mission_t0_s)
        self.stats.clock_published += 1
        self._sync_stats()

    def _republish_clock(self) -> bool:
        """The held clock again (lockstep); False without a bus."""
        if self.outputs is None:
            return False
        self._publish_clock(self.clock.now_s)
        return True

    def _sync_stats(self) -> None:
        em = self.emulator
        if em is not None:
            self.stats.detections_published = em.detections_published
            self.stats.plans_received = em.plans_received
            self.stats.plans_rejected = em.plans_rejected
            if em.last_error and not self.stats.last_error:
                self.stats.last_error = em.last_error
        self.stats.mission_t0_s = self.mission_t0_s
        self.stats.sim_time_s = self.clock.now_s


async def run_world(scenario: Scenario, options: WorldOptions, stop: asyncio.Event) -> WorldStats:
    """Run the world until `stop` is set; always closes the Zenoh session and the sockets.

    Usable in-process next to other tasks (the embedded `isac-mission run`). Returns counters.
    """
    world = World(scenario, options)
    try:
        await world.open()
        await world.run(stop)
    finally:
        await world.close()
    log.info(
        "world stopped at t = %.1f s after %d slots (%d plans, %d rejected, %d lockstep timeouts)",
        world.stats.sim_time_s,
        world.stats.slots,
        world.stats.plans_received,
        world.stats.plans_rejected,
        world.stats.lockstep_timeouts,
    )
    return world.stats
