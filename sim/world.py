"""The simulated world in one process: clock, vehicles, target, sensing, and its bus outputs.

`run_world(scenario, options, stop)` runs until `stop` is set:

- a `SimClock` (ticks of 1 / tick_hz simulation seconds at `speed` x real time) steps the M
  autopilots (`sim.autopilot.Autopilot`, one per UAV: spawned on the ground at the scenario's
  start points, MAVLink on 127.0.0.1, offboard link to mavlink_base_port + m and GCS link to
  gcs_base_port + m) and drives everything else;
- at each slot boundary t = t0 + n dt it advances the target to slot n (slot 0 is x0), draws and
  publishes every UAV's detection from the vehicles' actual horizontal positions
  (`sim.emulator.SensingEmulator`), and publishes `truth` and `clock`;
- `clock` is also published every 1 / clock_rate_hz simulation seconds (slot -1 before the
  mission starts).

Mission start (t0): "immediate" (default) starts slot 0 at t = 0 with the vehicles on the ground
at their start points; "offboard" starts it at the first tick at which every vehicle is armed, in
OFFBOARD and within `start_altitude_tol_m` of the flight altitude H (DESIGN.md: the vehicles take
off, reach their start points and enter offboard; the ground loop or any MAVLink client flies
them there).

Slot convention: plan n carries the waypoints the vehicles fly to during (n-1, n] and the shares
eta_n of slot n's detections; the ground publishes plan n+1 after processing slot n. Lockstep:
after publishing slot n (for n < N) the clock holds at t0 + n dt until plan n+1 (or a later
one) has arrived, or `lockstep_timeout_s` wall seconds have passed (counted, logged; the world
then goes on with the latest shares). While it holds, the clock message is repeated every
`HELD_CLOCK_PERIOD_S` wall seconds, so that a ground loop or bridges (re)started meanwhile learn
the time and the mission start (a restarted `serve --resume` plans its next slot from them).

Vehicle telemetry is not published on Zenoh here: it goes over MAVLink (the service's bridge
publishes it). The vehicles' local NED frames are all centred on the scenario origin (0, 0)
(north = y, east = x).
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from isac_mission.config import Scenario
from isac_mission.service.bus import BusSettings, Keys, ZenohBus
from isac_mission.timebase import UNPACED_SPEED, SlotTimeline, reached
from isac_mission.types import FloatArray
from isac_mission.wire import ClockMsg, TruthMsg, encode_clock, encode_truth
from sim.autopilot import (
    GCS_BASE_PORT,
    OFFBOARD_BASE_PORT,
    PX4_SITL_ORIGIN,
    Autopilot,
    AutopilotSettings,
    FlightMode,
    GeoPoint,
)
from sim.clock import SimClock
from sim.emulator import SensingEmulator
from sim.sensing import SensingModel, Sensor
from sim.target import CvTarget, ScriptedTarget, TargetModel
from sim.vehicle import VehicleLimits

log = logging.getLogger(__name__)

HELD_CLOCK_PERIOD_S = 0.5
"""Wall seconds between repeats of the clock message while the world holds in lockstep."""
StartMode = Literal["immediate", "offboard"]


@dataclass(frozen=True)
class LinkOutage:
    """Vehicle `vehicle`'s MAVLink radio is dead for `duration_s` simulation seconds from
    `start_s` after mission start (slot 0)."""

    vehicle: int
    start_s: float
    duration_s: float

    @classmethod
    def parse(cls, text: str) -> LinkOutage:
        """`M:START:DURATION`, e.g. `1:20:5` (vehicle 1, 20 s into the mission, for 5 s)."""
        parts = text.split(":")
        try:
            m, start, duration = int(parts[0]), float(parts[1]), float(parts[2])
            if len(parts) != 3 or m < 0 or start < 0 or duration <= 0:
                raise ValueError
        except (ValueError, IndexError):
            raise ValueError(
                f"link outage {text!r}: expected VEHICLE:START_S:DURATION_S, e.g. 1:20:5"
            ) from None
        return cls(m, start, duration)


def parse_outages(texts: Sequence[str], n_vehicles: int) -> tuple[LinkOutage, ...]:
    """LinkOutage.parse of each text, checked against the fleet size; ValueError names the bad one."""
    outages = tuple(LinkOutage.parse(text) for text in texts)
    for text, outage in zip(texts, outages, strict=True):
        if outage.vehicle >= n_vehicles:
            raise ValueError(
                f"link outage {text!r}: no vehicle {outage.vehicle} (M = {n_vehicles})"
            )
    return outages


@dataclass(frozen=True)
class WorldOptions:
    """How to run the world. Times are simulation seconds unless marked wall.

    speed: simulation seconds per wall second (math.inf: as fast as possible).
    lockstep: hold the clock at each slot boundary until the next slot's plan arrives.
    lockstep_timeout_s: wall seconds to wait for that plan before going on.
    seed: seed of the target and sensing noise (None: the scenario's seed).
    bus: Zenoh settings (default: peer connecting to tcp/127.0.0.1:7447).
    mavlink_base_port / gcs_base_port: vehicle m sends to 127.0.0.1:(base + m).
    tick_hz: physics rate (simulation Hz); clock_rate_hz: clock publication rate (simulation Hz).
    start: "immediate" or "offboard" (see the module docstring); start_altitude_tol_m: |alt - H|
    allowed for an "offboard" start.
    target_waypoints_xy_m / target_speed_mps: a scripted target path instead of the CV model
    (speed default: the speed of x0). reflect_target: keep the CV target inside the area.
    initial_error: start the CV target at x0 + e, e ~ N(0, P0), so that the tracker's prior
    (mean x0, covariance P0) is honest; False starts it exactly at x0.
    geo_origin: geodetic position of the scenario origin (GPS of the simulated vehicles).
    link_outages: scheduled MAVLink radio failures (fault injection, docs/reliability.md).
    """

    speed: float = 1.0
    lockstep: bool = False
    lockstep_timeout_s: float = 30.0
    seed: int | None = None
    bus: BusSettings = field(default_factory=BusSettings)
    mavlink_base_port: int = OFFBOARD_BASE_PORT
    gcs_base_port: int = GCS_BASE_PORT
    tick_hz: float = 50.0
    clock_rate_hz: float = 10.0
    start: StartMode = "immediate"
    start_altitude_tol_m: float = 2.0
    target_waypoints_xy_m: tuple[tuple[float, float], ...] | None = None
    target_speed_mps: float | None = None
    reflect_target: bool = True
    initial_error: bool = True
    geo_origin: GeoPoint = PX4_SITL_ORIGIN
    link_outages: tuple[LinkOutage, ...] = ()

    def __post_init__(self) -> None:
        if math.isnan(self.speed) or self.speed <= 0:
            raise ValueError(f"speed must be > 0 or inf, got {self.speed}")
        if not self.lockstep_timeout_s > 0:
            raise ValueError(f"lockstep_timeout_s must be > 0, got {self.lockstep_timeout_s}")
        if not (math.isfinite(self.tick_hz) and self.tick_hz > 0):
            raise ValueError(f"tick_hz must be finite and > 0, got {self.tick_hz}")
        if not (math.isfinite(self.clock_rate_hz) and self.clock_rate_hz > 0):
            raise ValueError(f"clock_rate_hz must be finite and > 0, got {self.clock_rate_hz}")
        if self.start not in ("immediate", "offboard"):
            raise ValueError(f"start must be immediate or offboard, got {self.start!r}")
        for name in ("mavlink_base_port", "gcs_base_port"):
            port = getattr(self, name)
            if not 1 <= port <= 65535 - 254:
                raise ValueError(f"{name} must leave room for 254 vehicles, got {port}")


@dataclass
class WorldStats:
    """Counters of a world run (returned by run_world)."""

    slots: int = 0
    mission_t0_s: float | None = None
    sim_time_s: float = 0.0
    detections_published: int = 0
    clock_published: int = 0
    truth_published: int = 0
    plans_received: int = 0
    plans_rejected: int = 0
    lockstep_holds: int = 0
    lockstep_timeouts: int = 0
    last_error: str = ""


def make_target(scenario: Scenario, options: WorldOptions, rng: np.random.Generator) -> TargetModel:
    """The target the options ask for: scripted path, or the CV model of the scenario."""
    bounds = scenario.area if options.reflect_target else None
    if options.target_waypoints_xy_m is not None:
        speed = options.target_speed_mps
        if speed is None:
            speed = float(np.hypot(scenario.x0[2], scenario.x0[3])) or 1.0
        return ScriptedTarget(
            options.target_waypoints_xy_m, speed, scenario.dt, bounds_m=scenario.area
        )
    x0 = scenario.x0
    if options.initial_error:
        # The configured x0 is the cue the tracker starts from; the truth differs from it by a
        # draw from P0, as in `simulate` (docs/model.md, "EKF start and P0").
        x0 = x0 + rng.multivariate_normal(np.zeros(4), scenario.P0)
    return CvTarget(x0, scenario.dt, scenario.kappa, rng, bounds_m=bounds)


def autopilot_settings(scenario: Scenario, options: WorldOptions, m: int) -> AutopilotSettings:
    """Vehicle m's settings: start point, flight altitude H, V_max, geofence = the area, and
    the scenario's MAVLink signing key (None: signing off)."""
    start = scenario.uav_start_xy[m]
    return AutopilotSettings(
        index=m,
        offboard_port=options.mavlink_base_port + m,
        gcs_port=options.gcs_base_port + m,
        geo_origin=options.geo_origin,
        local_origin_xy_m=(0.0, 0.0),
        spawn_xy_m=(float(start[0]), float(start[1])),
        takeoff_alt_m=scenario.H,
        limits=VehicleLimits(
            max_horizontal_speed_mps=scenario.v_max, max_horizontal_accel_mps2=scenario.a_max
        ),
        area_min_xy_m=(0.0, 0.0),
        area_max_xy_m=(float(scenario.area[0]), float(scenario.area[1])),
        max_altitude_m=max(500.0, 2.0 * scenario.H),
        signing=scenario.mavlink_signing_key,
    )


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
        seed = scenario.seed if options.seed is None else options.seed
        target_seq, sensing_seq = np.random.SeedSequence(seed).spawn(2)
        self.target = make_target(scenario, options, np.random.default_rng(target_seq))
        self.sensor = Sensor(
            SensingModel.from_scenario(scenario), np.random.default_rng(sensing_seq)
        )
        self.clock = SimClock(tick_hz=options.tick_hz, speed=options.speed)
        self.vehicles = [
            Autopilot(autopilot_settings(scenario, options, m)) for m in range(scenario.M)
        ]
        self.bus: ZenohBus | None = None
        self.emulator: SensingEmulator | None = None
        self.mission_t0_s: float | None = 0.0 if options.start == "immediate" else None
        self._outages_scheduled = False
        for outage in options.link_outages:
            if not 0 <= outage.vehicle < scenario.M:
                raise ValueError(f"link outage: no vehicle {outage.vehicle} (M = {scenario.M})")
        self._next_slot = 0
        self._next_clock_s = 0.0
        self._held_slot: int | None = None
        self._hold_timer: asyncio.TimerHandle | None = None
        self._held_clock_timer: asyncio.TimerHandle | None = None
        self._opened_vehicles: list[Autopilot] = []

    # -- lifecycle ---------------------------------------------------------------------------

    async def open(self) -> None:
        """Open the Zenoh session and the vehicles' MAVLink sockets."""
        self.bus = await ZenohBus.open_async(self.options.bus)
        self.emulator = SensingEmulator(
            self.bus, self.keys, self.sensor, self.scenario.M, n_bs=self.scenario.K
        )
        self.emulator.add_plan_listener(self._on_plan)
        for v in self.vehicles:
            await v.open()
            self._opened_vehicles.append(v)

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
            self._cancel_hold_timer()
            self._sync_stats()

    async def close(self) -> None:
        """Close the vehicles' sockets and the Zenoh session (idempotent)."""
        self._cancel_hold_timer()
        while self._opened_vehicles:
            v = self._opened_vehicles.pop()
            try:
                await v.close()
            except Exception as err:  # keep closing the rest
                log.warning("vehicle %d close: %s", v.system_id, err)
        if self.bus is not None:
            self.bus.close()

    # -- per tick ----------------------------------------------------------------------------

    def _on_tick(self, now_s: float, dt_s: float) -> None:
        for v in self.vehicles:
            v.step(now_s, dt_s)
        if self.mission_t0_s is None and self._ready_to_start():
            self.mission_t0_s = now_s
            log.info("mission start at t = %.2f s: all vehicles in offboard at altitude", now_s)
        if self.mission_t0_s is not None and not self._outages_scheduled:
            self._outages_scheduled = True
            for outage in self.options.link_outages:
                self.vehicles[outage.vehicle].silence_radio(
                    self.mission_t0_s + outage.start_s, outage.duration_s
                )
        self._run_due_slots(now_s)
        if reached(now_s, self._next_clock_s):
            self._publish_clock(now_s)

    def _ready_to_start(self) -> bool:
        tol = self.options.start_altitude_tol_m
        return all(
            v.state.armed
            and not v.state.landed
            and v.state.mode is FlightMode.OFFBOARD
            and abs(v.state.altitude_m - self.scenario.H) <= tol
            for v in self.vehicles
        )

    def _timeline(self) -> SlotTimeline:
        assert self.mission_t0_s is not None
        return SlotTimeline(self.mission_t0_s, self.scenario.dt)

    def _slot_time(self, n: int) -> float:
        return self._timeline().slot_end_s(n)

    def _run_due_slots(self, now_s: float) -> None:
        if self.mission_t0_s is None:
            return
        while self._held_slot is None and reached(now_s, self._slot_time(self._next_slot)):
            n = self._next_slot
            self._next_slot = n + 1
            self._run_slot(n, now_s)

    def _uav_xy(self) -> FloatArray:
        """[M, 2] actual horizontal positions (scenario plane, m)."""
        return np.array([v.state.position_xy_m for v in self.vehicles], dtype=float)

    def _run_slot(self, n: int, now_s: float) -> None:
        bus, emulator = self.bus, self.emulator
        assert bus is not None and emulator is not None
        t_s = self._slot_time(n)
        x = self.target.state if n == 0 else self.target.advance()
        if self.target.slot != n:  # the target is advanced exactly once per slot
            raise RuntimeError(f"target at slot {self.target.slot}, world at slot {n}")
        # Truth first, so that an evaluator has it when the slot's detections complete.
        bus.publish(self.keys.truth, encode_truth(TruthMsg(slot=n, t_s=t_s, target_x=x)))
        self.stats.truth_published += 1
        det = emulator.emit(n, t_s, x, self._uav_xy())
        self.stats.slots = n + 1
        self._publish_clock(now_s)
        log.debug(
            "slot %d at t = %.2f s: %d/%d detections", n, t_s, det.received.sum(), len(det.received)
        )
        if self.options.lockstep and n < self.scenario.N and emulator.latest_plan_slot < n + 1:
            self._hold(n, now_s)

    # -- lockstep ----------------------------------------------------------------------------

    def _hold(self, n: int, now_s: float) -> None:
        self._held_slot = n
        self.stats.lockstep_holds += 1
        self.clock.hold_at(now_s)
        loop = asyncio.get_running_loop()
        self._hold_timer = loop.call_later(self.options.lockstep_timeout_s, self._hold_timeout, n)
        self._held_clock_timer = loop.call_later(HELD_CLOCK_PERIOD_S, self._repeat_held_clock, n)

    def _repeat_held_clock(self, n: int) -> None:
        """Publish the held clock again (and again) while slot n holds."""
        self._held_clock_timer = None
        if self._held_slot != n or self.bus is None:
            return
        self._publish_clock(self.clock.now_s)
        loop = asyncio.get_running_loop()
        self._held_clock_timer = loop.call_later(HELD_CLOCK_PERIOD_S, self._repeat_held_clock, n)

    def _release(self) -> None:
        self._cancel_hold_timer()
        self._held_slot = None
        self.clock.release(self.clock.now_s)

    def _on_plan(self, plan: object) -> None:
        emulator = self.emulator
        assert emulator is not None
        if self._held_slot is not None and emulator.latest_plan_slot >= self._held_slot + 1:
            self._release()

    def _hold_timeout(self, n: int) -> None:
        self._hold_timer = None
        if self._held_slot != n:
            return
        self.stats.lockstep_timeouts += 1
        self.stats.last_error = (
            f"lockstep: no plan for slot {n + 1} within {self.options.lockstep_timeout_s} s"
        )
        log.warning("%s; going on with the latest shares", self.stats.last_error)
        self._release()

    def _cancel_hold_timer(self) -> None:
        if self._hold_timer is not None:
            self._hold_timer.cancel()
            self._hold_timer = None
        if self._held_clock_timer is not None:
            self._held_clock_timer.cancel()
            self._held_clock_timer = None

    # -- outputs -----------------------------------------------------------------------------

    def _current_slot(self, now_s: float) -> int:
        if self.mission_t0_s is None or not reached(now_s, self.mission_t0_s):
            return -1
        return min(self._next_slot - 1, max(0, self._timeline().slot_of(now_s)))

    def _publish_clock(self, now_s: float) -> None:
        bus = self.bus
        assert bus is not None
        msg = ClockMsg(
            slot=self._current_slot(now_s),
            t_s=now_s,
            slot_s=self.scenario.dt,
            speed=self.options.speed if math.isfinite(self.options.speed) else UNPACED_SPEED,
            mission_t0_s=self.mission_t0_s,
        )
        bus.publish(self.keys.clock, encode_clock(msg))
        self.stats.clock_published += 1
        period = 1.0 / self.options.clock_rate_hz
        clock_grid = SlotTimeline(0.0, period)
        self._next_clock_s = clock_grid.slot_end_s(clock_grid.slot_of(now_s) + 1)
        self._sync_stats()

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
