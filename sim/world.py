"""The simulated world in one process: clock, vehicles, target, sensing, and its bus outputs.

`run_world(scenario, options, stop)` runs until `stop` is set:

- a `SimClock` (ticks of 1 / tick_hz simulation seconds at `speed` x real time) steps the M
  autopilots (`sim.autopilot.Autopilot`, one per UAV: spawned on the ground at the scenario's
  start points, MAVLink on 127.0.0.1 in PX4 SITL's layout: offboard link from
  mavlink_local_base_port + m to mavlink_base_port + m, GCS link from gcs_local_base_port + m
  to gcs_port) and drives everything else;
- at each slot boundary t = t0 + n dt it advances the target to slot n (slot 0 is x0), draws and
  publishes every UAV's detection from the vehicles' actual horizontal positions
  (`sim.emulator.SensingEmulator`), and publishes `truth` and `clock`; on a multi-target mission
  every UAV's unlabelled report (`detection_set`) and every target's truth (`truth_set`) of
  `sim.multi_target_scene` instead;
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

The parts: options and counters `sim.world_options`, target, sensor and vehicles
`sim.world_assembly`, truth and clock publishing `sim.world_outputs`, detections
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
from sim.multi_target_scene import MultiTargetScene
from sim.world_assembly import (
    make_target_and_sensor,
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
        self.target, self.sensor = make_target_and_sensor(scenario, options)
        self.scene: MultiTargetScene | None = None
        """The targets of a multi-target mission (`simulate`'s draws for the world's seed); the
        single `target` then stays unused."""
        if scenario.multi_target:
            seed = scenario.seed if options.seed is None else options.seed
            self.scene = MultiTargetScene(scenario, seed)
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
            self.detection_links or self.bus,
            self.keys,
            self.sensor,
            self.scenario.M,
            n_bs=self.scenario.K,
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
        outputs, emulator = self.outputs, self.emulator
        assert outputs is not None and emulator is not None
        t_s = self._slot_time(n)
        if self.scene is not None:
            self._run_multi_target_slot(n, now_s, t_s, self.scene)
            return
        x = self.target.state if n == 0 else self.target.advance()
        if self.target.slot != n:  # the target is advanced exactly once per slot
            raise RuntimeError(f"target at slot {self.target.slot}, world at slot {n}")
        # Truth first, so that an evaluator has it when the slot's detections complete.
        outputs.publish_truth(n, t_s, x)
        self.stats.truth_published += 1
        det = emulator.emit(n, t_s, x, positions_xy_m(self.vehicles))
        self.stats.slots = n + 1
        self._publish_clock(now_s)
        log.debug(
            "slot %d at t = %.2f s: %d/%d detections", n, t_s, det.received.sum(), len(det.received)
        )
        if self.options.lockstep and n < self.scenario.N and emulator.latest_plan_slot < n + 1:
            self.lockstep.hold(n, now_s)

    def _run_multi_target_slot(
        self, n: int, now_s: float, t_s: float, scene: MultiTargetScene
    ) -> None:
        """Slot n of a multi-target mission: every target's truth with the origins of the
        slot's measurements (first, as on a single-target mission), then every UAV's unlabelled
        report (slots 1..N; slot 0 is before plan 1 and has none). Past slot N the world shows
        nothing more."""
        outputs, emulator = self.outputs, self.emulator
        assert outputs is not None and emulator is not None
        if scene.covers(n):
            xy = positions_xy_m(self.vehicles)
            reports, eta = emulator.draw_reports(n, scene, xy) if n > 0 else ([], None)
            outputs.publish_truth_set(n, t_s, scene.truth(n), reports)
            self.stats.truth_published += 1
            if eta is not None:
                emulator.publish_reports(n, t_s, reports, xy, eta)
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
