"""`BridgeFleet`: M vehicle bridges on one Zenoh session and one time source, following plans.

`start()`, `prepare_all()`, `on_plan(plan)` (or `follow_plans()`, which subscribes to
`isac/<mission>/plan`), `land_all()`, `stop()`. Plan n's waypoints are to be reached by the end
of slot n (t0 + n dt from the clock's slot timeline); plans not newer than the last one are
dropped and counted, and so are plans that come more than `LATE_PLAN_SLOTS` after their slot
ended (a ground station that stalled: its plan is for a past the vehicles have left).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Coroutine, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from isac_mission.bus import BusSettings, ZenohBus
from isac_mission.config import Scenario
from isac_mission.errors import IsacError, LinkError, MessageError
from isac_mission.mavwire.ports import OFFBOARD_BASE_PORT
from isac_mission.service.bridge.clock_time import close_bus_and_clock, open_bus_and_clock
from isac_mission.service.bridge.counters import FleetCounters
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.vehicle import VehicleBridge
from isac_mission.timebase import SimTime, plan_is_late
from isac_mission.types import FloatArray
from isac_mission.wire import FleetMsg, Keys, PlanMsg, decode

log = logging.getLogger(__name__)


@dataclass
class _FleetPlanState:
    last_slot: int = -1
    counters: FleetCounters = field(default_factory=FleetCounters)


class BridgeFleet:
    """M `VehicleBridge`s on one Zenoh session and one time source.

    Args:
        settings: One BridgeSettings per vehicle, index m at position m.
        time: Simulation time shared by the bridges.
        keys: The mission's Zenoh keys.
        bus: A Zenoh session owned by the caller; None = open one with `bus_settings`.
        slot_s: Slot length, s: the deadline of a plan when the time source does not know
            the mission start (plan n then arrives by now + slot_s).
        start_xy_m: [M, 2] default start points of `prepare_all`.
        altitude_m: Default mission altitude of `prepare_all`, m.
    """

    def __init__(
        self,
        settings: Sequence[BridgeSettings],
        time: SimTime,
        keys: Keys,
        bus: ZenohBus | None = None,
        *,
        bus_settings: BusSettings | None = None,
        slot_s: float = 1.0,
        start_xy_m: FloatArray | None = None,
        altitude_m: float | None = None,
    ) -> None:
        if not settings:
            raise IsacError("BridgeFleet: no vehicles")
        for m, s in enumerate(settings):
            if s.index != m:
                raise IsacError(f"BridgeFleet: settings[{m}] has index {s.index}")
        self.time = time
        self.keys = keys
        self.slot_s = float(slot_s)
        self.start_xy_m = None if start_xy_m is None else np.array(start_xy_m, dtype=float)
        self.altitude_m = altitude_m
        self._bus = bus
        self._own_bus = bus is None
        self._bus_settings = bus_settings
        self._settings = list(settings)
        self.bridges: list[VehicleBridge] = []
        self._plans = _FleetPlanState()
        self._started_clock = False

    @classmethod
    def from_scenario(
        cls,
        scenario: Scenario,
        time: SimTime,
        bus: ZenohBus | None = None,
        *,
        base_port: int = OFFBOARD_BASE_PORT,
        origins_xy_m: Sequence[tuple[float, float]] | None = None,
        bus_settings: BusSettings | None = None,
        links: Mapping[int, str] | None = None,
        **overrides: Any,
    ) -> BridgeFleet:
        """M bridges for `scenario`: V_max, vehicle m on base_port + m with system id m + 1,
        local origins `origins_xy_m` (default: the scenario origin for all), start points and
        altitude H for `prepare_all`, the scenario's MAVLink signing key, vehicle m's link URL
        `links[m]` if given (a serial device, `isac_mission.mavwire.serial_link`); `overrides`
        go to every BridgeSettings."""
        if origins_xy_m is not None and len(origins_xy_m) != scenario.M:
            raise IsacError(f"origins_xy_m: {len(origins_xy_m)} origins for M = {scenario.M}")
        settings = [
            BridgeSettings(
                index=m,
                base_port=base_port,
                origin_xy_m=origins_xy_m[m] if origins_xy_m is not None else (0.0, 0.0),
                v_max_mps=scenario.v_max,
                link=(links or {}).get(m),
                **{"signing": scenario.mavlink_signing_key, **overrides},
            )
            for m in range(scenario.M)
        ]
        return cls(
            settings,
            time,
            Keys(scenario.mission_id),
            bus,
            bus_settings=bus_settings,
            slot_s=scenario.dt,
            start_xy_m=scenario.uav_start_xy,
            altitude_m=scenario.H,
        )

    @property
    def counters(self) -> FleetCounters:
        """Plan counters."""
        return self._plans.counters

    @property
    def bus(self) -> ZenohBus:
        """The shared Zenoh session (RuntimeError before start() when the fleet opens it)."""
        if self._bus is None:
            raise RuntimeError("BridgeFleet: no bus before start()")
        return self._bus

    async def start(self) -> None:
        """Open the bus if needed, start the time source's subscription and every bridge."""
        if self.bridges:
            return
        try:
            self._bus, started = await open_bus_and_clock(
                self._bus, self._bus_settings, self.time, self.keys
            )
            self._started_clock = self._started_clock or started
            for s in self._settings:
                bridge = VehicleBridge(s, self.time, self.keys, self._bus)
                self.bridges.append(bridge)
                await bridge.start()
        except BaseException:
            await self.stop()
            raise

    async def stop(self) -> None:
        """Stop every bridge, the clock subscription and the fleet's own bus (idempotent)."""
        bridges, self.bridges = self.bridges, []
        for bridge in bridges:
            await bridge.stop()
        await close_bus_and_clock(
            self._bus if self._own_bus else None, self.time if self._started_clock else None
        )
        self._started_clock = False
        if self._own_bus:
            self._bus = None

    async def __aenter__(self) -> BridgeFleet:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    async def _all(self, make: Callable[[VehicleBridge], Awaitable[None]], what: str) -> None:
        """Run `make(bridge)` for every bridge concurrently; LinkError listing the failures."""

        async def one(b: VehicleBridge) -> None:
            await make(b)

        coros: list[Coroutine[Any, Any, None]] = [one(b) for b in self.bridges]
        results = await asyncio.gather(*coros, return_exceptions=True)
        failures = [
            f"vehicle {b.index}: {r}"
            for b, r in zip(self.bridges, results, strict=True)
            if isinstance(r, BaseException)
        ]
        for r in results:
            if isinstance(r, BaseException) and not isinstance(r, Exception):
                raise r  # cancellation and friends pass through
        if failures:
            raise LinkError(f"{what} failed: " + "; ".join(failures))

    async def prepare_all(
        self, start_xy_m: FloatArray | None = None, altitude_m: float | None = None
    ) -> None:
        """`prepare` every vehicle concurrently: start_xy_m [M, 2] (default: the fleet's start
        points) at `altitude_m` (default: the fleet's altitude). LinkError if any fails."""
        starts = self.start_xy_m if start_xy_m is None else np.asarray(start_xy_m, dtype=float)
        alt = self.altitude_m if altitude_m is None else altitude_m
        if starts is None or alt is None:
            raise IsacError("prepare_all: no start points or altitude given")
        if starts.shape != (len(self.bridges), 2):
            raise IsacError(f"prepare_all: start_xy_m has shape {starts.shape}")
        await self._all(lambda b: b.prepare(starts[b.index], alt), "prepare")

    async def land_all(self) -> None:
        """`land` every vehicle concurrently; LinkError if any fails."""
        await self._all(lambda b: b.land(), "land")

    async def hold_all(self) -> None:
        """`hold` every vehicle concurrently; LinkError if any fails."""
        await self._all(lambda b: b.hold(), "hold")

    def deadline_s(self, slot: int) -> float:
        """When plan `slot`'s waypoints must be reached: t0 + slot * dt from the world's slot
        clock, or now + slot_s when the time follows none or the mission start is unknown
        (simulation seconds)."""
        end = self.time.slot_end_s(slot)
        if end is not None:
            return end
        return self.time.now_s() + self.slot_s

    def on_plan(self, plan: PlanMsg, arrive_by_s: float | None = None) -> bool:
        """Send each vehicle toward its waypoint of `plan` (plan.plan.uav_xy_m [M, 2]) by
        `arrive_by_s` (default `deadline_s(plan.slot)`), at its planned end velocity
        (plan.plan.uav_velocity_mps [M, 2]) when the plan has one. Plans not newer than the
        last one are dropped (counted). True if applied."""
        st = self._plans
        waypoints = np.asarray(plan.plan.uav_xy_m, dtype=float)
        v = plan.plan.uav_velocity_mps
        velocities = None if v is None else np.asarray(v, dtype=float)
        shape = (len(self.bridges), 2)
        if waypoints.shape != shape or (velocities is not None and velocities.shape != shape):
            st.counters.plans_invalid += 1
            got = (
                waypoints.shape
                if velocities is None or waypoints.shape != shape
                else velocities.shape
            )
            st.counters.last_error = f"plan {plan.slot}: waypoints or velocities of shape {got}"
            log.warning("%s", st.counters.last_error)
            return False
        if plan.slot <= st.last_slot:
            st.counters.plans_stale += 1
            return False
        end = self.time.slot_end_s(plan.slot)  # None: no slot clock, or t0 not known yet
        if arrive_by_s is None and plan_is_late(end, self.time.now_s(), self.slot_s):
            st.counters.plans_late += 1
            st.counters.last_error = f"plan {plan.slot}: its slot ended at {end:.1f} s; dropped"
            log.warning("%s", st.counters.last_error)
            return False
        st.last_slot = plan.slot
        deadline = self.deadline_s(plan.slot) if arrive_by_s is None else arrive_by_s
        for bridge in self.bridges:
            bridge.plan_slot = plan.slot
            planned_v = None if velocities is None else velocities[bridge.index]
            bridge.set_waypoint(waypoints[bridge.index], deadline, planned_v)
        st.counters.plans_applied += 1
        return True

    async def follow_plans(self) -> None:
        """Apply every valid plan published on `isac/<mission>/plan`, and carry out the ground
        loop's fleet commands (`isac/<mission>/fleet`), until cancelled (invalid payloads are
        counted, logged and dropped)."""
        async with asyncio.TaskGroup() as tg:
            tg.create_task(self._follow_fleet_commands())
            await self._follow_plan_key()

    async def _follow_plan_key(self) -> None:
        n = len(self.bridges)
        async with self.bus.subscribe(self.keys.plan, maxsize=16) as sub:
            async for _key, payload in sub:
                try:
                    plan = decode(PlanMsg, payload, n_uavs=n)
                except MessageError as err:
                    self.counters.plans_invalid += 1
                    self.counters.last_error = str(err)
                    log.warning("plan dropped: %s", err)
                    continue
                self.on_plan(plan)

    async def _follow_fleet_commands(self) -> None:
        """hold, resume, land, release for the listed vehicles, each as its own task."""
        n = len(self.bridges)
        running: set[asyncio.Task[None]] = set()
        try:
            await self._fleet_loop(n, running)
        finally:
            for task in running:
                task.cancel()

    async def _fleet_loop(self, n: int, running: set[asyncio.Task[None]]) -> None:
        async with self.bus.subscribe(self.keys.fleet, maxsize=16) as sub:
            async for _key, payload in sub:
                try:
                    msg = decode(FleetMsg, payload, n_uavs=n)
                except MessageError as err:
                    self.counters.fleet_invalid += 1
                    self.counters.last_error = str(err)
                    log.warning("fleet command dropped: %s", err)
                    continue
                for m in msg.uavs:
                    task = asyncio.create_task(
                        self.bridges[m].on_fleet(msg.command, msg.request_id),
                        name=f"fleet-{msg.command}-{m}",
                    )
                    running.add(task)
                    task.add_done_callback(running.discard)
