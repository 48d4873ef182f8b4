"""A rig for the MAVLink bridge tests: simulated PX4-like vehicles with a Zenoh clock.

Vehicles run on a SimClock at `SPEED` x real time in the sim harness's thread (`sim_runner`); a
tick callback publishes the `clock` on a Zenoh hub session as the world does, so the bridges'
`ClockSimTime` follows real clock messages. `BoundaryRecorder` snapshots the vehicles at chosen
simulation times and signals each to the test's event loop (no sleeps to synchronise).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from isac_mission.bus import ZenohBus
from isac_mission.service.bridge.clock_time import ClockSimTime
from isac_mission.service.bridge.settings import BridgeSettings
from isac_mission.service.bridge.vehicle import VehicleBridge
from isac_mission.timebase import SlotTimeline, reached
from isac_mission.wire import ClockMsg, Keys, TelemetryMsg, decode, encode
from sim.autopilot.endpoint import Autopilot
from sim.autopilot.settings import AutopilotSettings
from tests.support.ports import free_udp_ports
from tests.support.sim_harness import SimRunner

SPEED = 10.0
"""Simulation seconds per wall second (the default; `rig(..., speed=)` for another)."""
ALTITUDE_M = 10.0
V_MAX_MPS = 12.0  # the simulated airframe's MPC_XY_VEL_MAX
CLOCK_PERIOD_S = 0.1  # the world publishes its clock at 10 Hz of simulation time
CLOCK_GRID = SlotTimeline(0.0, CLOCK_PERIOD_S)
TIMEOUT_S = 30.0  # wall seconds for any single awaited event
ARRIVE_TOL_M = 1.5
MIN_RATE_HZ = 10.0
KEYS = Keys("bridge-test")


class ClockPublisher:
    """SimClock tick callback (sim thread): the world's `clock` message every 0.1 s sim."""

    def __init__(self, bus: ZenohBus, slot_s: float, speed: float = SPEED) -> None:
        self.bus = bus
        self.slot_s = slot_s
        self.speed = speed
        self.mission_t0_s: float | None = None
        self._next_s = 0.0

    def __call__(self, now_s: float, dt_s: float) -> None:
        if not reached(now_s, self._next_s) or self.bus.closed:
            return
        self._next_s = CLOCK_GRID.slot_end_s(CLOCK_GRID.slot_of(now_s) + 1)
        t0 = self.mission_t0_s
        slot = -1 if t0 is None or now_s < t0 else SlotTimeline(t0, self.slot_s).slot_of(now_s)
        msg = ClockMsg(slot=slot, t_s=now_s, slot_s=self.slot_s, speed=self.speed, mission_t0_s=t0)
        with contextlib.suppress(RuntimeError):  # the bus closed meanwhile
            self.bus.publish(KEYS.clock, encode(msg))


@dataclass
class Snapshot:
    """What the vehicles and the bridges were at a simulation time (taken on the sim thread)."""

    time_s: float
    states: list[Any]
    setpoints_sent: list[int]


class BoundaryRecorder:
    """SimClock tick callback (sim thread): snapshots at chosen simulation times, each
    signalled to the test's event loop through an asyncio.Event."""

    def __init__(self, runner: SimRunner, bridges: list[VehicleBridge]) -> None:
        self.runner = runner
        self.bridges = bridges
        self.loop = asyncio.get_running_loop()
        self._lock = threading.Lock()
        self._watch: list[tuple[float, asyncio.Event]] = []
        self.snapshots: dict[float, Snapshot] = {}

    def watch(self, t_s: float) -> asyncio.Event:
        event = asyncio.Event()
        with self._lock:
            self._watch.append((t_s, event))
        return event

    def __call__(self, now_s: float, dt_s: float) -> None:
        with self._lock:
            due = [(t, e) for t, e in self._watch if reached(now_s, t)]
            self._watch = [(t, e) for t, e in self._watch if not reached(now_s, t)]
        for t_s, event in due:
            self.snapshots[t_s] = Snapshot(
                now_s,
                [ap.state for ap in self.runner.autopilots],
                [b.counters.setpoints_sent for b in self.bridges],
            )
            self.loop.call_soon_threadsafe(event.set)


@dataclass
class Rig:
    """Simulated vehicles with a Zenoh clock, and the ports their bridges must bind."""

    runner: SimRunner
    hub: ZenohBus
    clock: ClockPublisher
    bridge_ports: list[int]
    bridges: list[VehicleBridge] = field(default_factory=list)

    @property
    def vehicle(self) -> Autopilot:
        return self.runner.autopilots[0]

    def now_s(self) -> float:
        """True simulation time (the vehicles' clock)."""
        return self.runner.clock.now_s

    def bridge(self, m: int = 0, **overrides: Any) -> VehicleBridge:
        settings = BridgeSettings(
            index=m, port=self.bridge_ports[m], v_max_mps=V_MAX_MPS, **overrides
        )
        bridge = VehicleBridge(settings, ClockSimTime(), KEYS, self.hub)
        self.bridges.append(bridge)
        return bridge

    def recorder(self) -> BoundaryRecorder:
        rec = BoundaryRecorder(self.runner, self.bridges)
        self.runner.call(lambda: self.runner.clock.add_tick_callback(rec))
        return rec


def make_rig(sim_runner: Callable[..., SimRunner], hub: ZenohBus) -> Callable[..., Rig]:
    """Factory (for a test module's `rig` fixture): `rig(spawn_xy_m=[(x, y)],
    **autopilot_settings)` starts the vehicles."""

    def make(
        spawn_xy_m: list[tuple[float, float]],
        slot_s: float = 1.0,
        speed: float = SPEED,
        **overrides: Any,
    ) -> Rig:
        n = len(spawn_xy_m)
        ports = free_udp_ports(2 * n)
        settings = [
            AutopilotSettings(
                index=m,
                offboard_port=ports[m],
                gcs_port=ports[n + m],
                spawn_xy_m=spawn_xy_m[m],
                **({"bind_port": 0, "gcs_bind_port": 0} | overrides),
            )
            for m in range(n)
        ]
        runner = sim_runner(settings, speed=speed)
        clock = ClockPublisher(hub, slot_s, speed)
        runner.call(lambda: runner.clock.add_tick_callback(clock))
        return Rig(runner, hub, clock, ports[:n])

    return make


async def next_telemetry(
    sub: Any, condition: Callable[[TelemetryMsg], bool] = lambda t: True
) -> TelemetryMsg:
    """The next telemetry message satisfying `condition` (TimeoutError after TIMEOUT_S)."""
    deadline = time.monotonic() + TIMEOUT_S
    while True:
        _, payload = await sub.get(max(0.01, deadline - time.monotonic()))
        msg = decode(TelemetryMsg, payload)
        if condition(msg):
            return msg


def distance_m(a: Any, b: Any) -> float:
    return float(np.hypot(*(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))
